"""The write-up's sections, one module each, in the order of the report.

Each module's ``build(ctx)`` takes the :class:`~clonedrive.report.context.ReportContext` and
returns its sections (a heading with a one-line note when its inputs are missing);
``clonedrive.report.writeup`` runs them in order and writes the document.
"""
