"""Whole recipes: what to record, how to train and how to drive, in one versioned TOML file.

``best`` and ``writeup`` ship with the package (``best.toml``, ``writeup.toml`` here);
:func:`clonedrive.recipes.book.load_recipe_file` reads those by name or any copy a user edits.
"""
