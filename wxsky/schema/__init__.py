"""The one settings checker: every config key, preset field, cloud-model key and control
parameter is checked by these kinds and tables, each limit written once by its owner.

Stdlib only, so every room (the pure weather and scene included) may use it.
"""

from wxsky.schema.kinds import Bool, Custom, Items, Kind, Number, Text, fmt_number
from wxsky.schema.problems import Invalid, KeyPath, Problem, format_key

__all__ = [
    "Bool",
    "Custom",
    "Invalid",
    "Items",
    "KeyPath",
    "Kind",
    "Number",
    "Problem",
    "Text",
    "fmt_number",
    "format_key",
]
