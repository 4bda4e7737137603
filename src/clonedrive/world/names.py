"""The forms a track name takes, as text for help and error messages (no imports: the CLI's
help reads it without loading the track generators)."""

from __future__ import annotations

#: The generated tracks' name forms (:mod:`clonedrive.world.catalog` parses them).
GENERATED_NAMES = "gen:<seed>, gen1:<seed>, gen2:<seed> or gen2:<easy|medium|hard>:<seed>"
#: What a ``--track`` option accepts, for every verb's help.
TRACK_NAMES_HELP = f"lake, mountain, {GENERATED_NAMES}, or a track .json file"
