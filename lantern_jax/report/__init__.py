"""Tables and files of an evaluation.

* :mod:`lantern_jax.report.tables` renders the tables as text: the per-family CUS table (with
  each model's paired warning gain), the CUS decomposition, the premise table and the ablation
  table, for the terminal or (``tablefmt="github"``) as Markdown, with their intervals.
* :mod:`lantern_jax.report.outputs` writes every file of an evaluation (or of the ablation
  table) into one folder as a whole set, byte-identical for the same inputs on the same
  machine: the route-level CSV and its schema, the tables as CSV and Markdown, a run record and
  the reproducibility manifest.

Every public name of both is importable from here (``from lantern_jax.report import
write_outputs``).
"""

from lantern_jax.report.outputs import (
    ABLATION_CSV,
    ABLATION_FILES,
    ABLATION_MANIFEST,
    ABLATION_MD,
    ABLATION_ROUTE_CSV,
    CSV_FLOAT_FORMAT,
    DECOMPOSITION_CSV,
    DECOMPOSITION_MD,
    FAMILY_CSV,
    FAMILY_MD,
    MANIFEST_JSON,
    OUTPUT_FILES,
    ROUTE_CSV,
    RUN_RECORD_JSON,
    RUN_RECORD_KEYS,
    check_output_folder,
    split_manifest,
    with_interval_columns,
    write_ablation_outputs,
    write_outputs,
    write_tables,
)
from lantern_jax.report.tables import (
    CONDITION_ORDER,
    FAMILY_COLUMNS,
    FLAG,
    GAIN_CONDITION,
    MISSING,
    PAIRS_STRATIFIED,
    family_columns,
    format_ablation_table,
    format_decomposition,
    format_family_table,
    format_interval,
    format_premise_table,
    format_tables,
    interval_display,
    interval_note,
    missing_shown,
    order_rows,
    ordered_tables,
)

__all__ = [
    "ABLATION_CSV",
    "ABLATION_FILES",
    "ABLATION_MANIFEST",
    "ABLATION_MD",
    "ABLATION_ROUTE_CSV",
    "CONDITION_ORDER",
    "CSV_FLOAT_FORMAT",
    "DECOMPOSITION_CSV",
    "DECOMPOSITION_MD",
    "FAMILY_COLUMNS",
    "FAMILY_CSV",
    "FAMILY_MD",
    "FLAG",
    "GAIN_CONDITION",
    "MANIFEST_JSON",
    "MISSING",
    "missing_shown",
    "OUTPUT_FILES",
    "PAIRS_STRATIFIED",
    "ROUTE_CSV",
    "RUN_RECORD_JSON",
    "RUN_RECORD_KEYS",
    "check_output_folder",
    "family_columns",
    "format_ablation_table",
    "format_decomposition",
    "format_family_table",
    "format_interval",
    "format_premise_table",
    "format_tables",
    "interval_display",
    "interval_note",
    "order_rows",
    "ordered_tables",
    "split_manifest",
    "with_interval_columns",
    "write_ablation_outputs",
    "write_outputs",
    "write_tables",
]
