"""The one settings checker: every config key, preset field, cloud-model key and control
parameter is checked by these kinds and tables, each limit written once by its owner (the
weather state, the camera, the config), and every problem of a file is reported at once as
`FILE:LINE: key: problem`.

Stdlib only, so every room (the pure weather and scene included) may use it.
"""

from wxsky.schema.kinds import (
    Bool,
    Custom,
    Items,
    Kind,
    Nullable,
    Number,
    Text,
    Tuple,
    fmt_number,
)
from wxsky.schema.problems import Invalid, KeyPath, Problem, format_key
from wxsky.schema.tables import OMIT, REQUIRED, Field, Rule, Table, Tables

__all__ = [
    "OMIT",
    "REQUIRED",
    "Bool",
    "Custom",
    "Field",
    "Invalid",
    "Items",
    "KeyPath",
    "Kind",
    "Nullable",
    "Number",
    "Problem",
    "Rule",
    "Table",
    "Tables",
    "Text",
    "Tuple",
    "fmt_number",
    "format_key",
]
