"""Write configs/wxsky-canaerospace.dbc from the CANaerospace id table
(wxsky/protocols/canaerospace_ids.py), for SavvyCAN, cantools and other DBC tools.

    .venv/bin/python tools/generate/build_dbc.py          # rewrite the file
    .venv/bin/python tools/generate/build_dbc.py --check  # exit 1: the file differs from the table
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT))

from wxsky.protocols.canaerospace_dbc import dbc_text  # noqa: E402

OUT = ROOT / "configs" / "wxsky-canaerospace.dbc"


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawTextHelpFormatter)
    p.add_argument("--check", action="store_true", help="compare only; exit 1 on a difference")
    p.add_argument("--out", type=Path, default=OUT, help=f"default {OUT.relative_to(ROOT)}")
    args = p.parse_args(argv)
    text = dbc_text()
    if args.check:
        # Bytes, not text: a checkout that turned LF into CRLF counts as a difference.
        current = args.out.read_bytes() if args.out.exists() else None
        if current != text.encode("ascii"):
            print(f"{args.out} is out of date: run tools/generate/build_dbc.py", file=sys.stderr)
            return 1
        print(f"{args.out} is up to date")
        return 0
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_bytes(text.encode("ascii"))
    messages = sum(line.startswith("BO_ ") for line in text.splitlines())
    print(f"wrote {args.out}: {messages} messages")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
