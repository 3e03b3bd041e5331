"""A dome's certificates for the authenticated channel bus (docs/channels.md), with openssl.

    .venv/bin/python tools/generate/dome_certs.py OUT --master-address 10.0.0.1 \\
        --channels left2,left1,centre,right1,right2

writes into OUT: `ca.pem` and `ca.key` (a private certificate authority: keep `ca.key` off
the IG machines), `master.pem`/`master.key` (common name `wxsky-master`, valid for the
master's addresses, which channels check when they connect) and per channel
`NAME.pem`/`NAME.key` (common name `wxsky-channel`: the master's access control grants a
channel's rights to that name). Keys are EC P-256, certificates valid for `--days` days.
Every file is written once: an existing one is an error (a new CA would orphan the others).
"""

from __future__ import annotations

import argparse
import ipaddress
import re
import shutil
import subprocess
import sys
import tempfile
from pathlib import Path

MASTER_CN = "wxsky-master"
CHANNEL_CN = "wxsky-channel"
NAME = re.compile(r"[a-z0-9][a-z0-9_-]{0,63}")


def _openssl(*args: str) -> None:
    subprocess.run(["openssl", *args], check=True, capture_output=True, text=True)


def _key(path: Path) -> None:
    _openssl(
        "genpkey", "-algorithm", "EC", "-pkeyopt", "ec_paramgen_curve:P-256", "-out", str(path)
    )
    path.chmod(0o600)


def _san(addresses: list[str]) -> str:
    entries = []
    for a in addresses:
        try:
            ipaddress.ip_address(a)
        except ValueError:
            entries.append(f"DNS:{a}")
        else:
            entries.append(f"IP:{a}")
    return ",".join(entries)


def _signed(out: Path, name: str, cn: str, san: str, days: int, work: Path) -> None:
    key, csr, ext = out / f"{name}.key", work / f"{name}.csr", work / f"{name}.ext"
    _key(key)
    _openssl("req", "-new", "-key", str(key), "-subj", f"/CN={cn}", "-out", str(csr))
    ext.write_text(
        "basicConstraints=CA:FALSE\n"
        "keyUsage=digitalSignature,keyEncipherment\n"
        "extendedKeyUsage=serverAuth,clientAuth\n" + (f"subjectAltName={san}\n" if san else "")
    )
    _openssl(
        "x509",
        "-req",
        "-in",
        str(csr),
        "-CA",
        str(out / "ca.pem"),
        "-CAkey",
        str(out / "ca.key"),
        "-CAcreateserial",
        "-days",
        str(days),
        "-extfile",
        str(ext),
        "-out",
        str(out / f"{name}.pem"),
    )


def generate(out: Path, master_addresses: list[str], channels: list[str], days: int) -> list[Path]:
    """Write the CA, the master's and each channel's certificate and key; returns the files."""
    names = ["ca", "master", *channels]
    clash = [n for n in names for s in (".pem", ".key") if (out / f"{n}{s}").exists()]
    if clash:
        raise FileExistsError(f"{out}: {clash[0]}.pem/.key exists; remove it or pick another OUT")
    out.mkdir(parents=True, exist_ok=True)
    with tempfile.TemporaryDirectory() as tmp:
        work = Path(tmp)
        _key(out / "ca.key")
        _openssl(
            "req",
            "-x509",
            "-new",
            "-key",
            str(out / "ca.key"),
            "-subj",
            "/CN=wxsky dome CA",
            "-days",
            str(days),
            "-addext",
            "basicConstraints=critical,CA:TRUE",
            "-addext",
            "keyUsage=critical,keyCertSign,cRLSign",
            "-out",
            str(out / "ca.pem"),
        )
        _signed(out, "master", MASTER_CN, _san(master_addresses), days, work)
        for name in channels:
            _signed(out, name, CHANNEL_CN, "", days, work)
    (out / "ca.srl").unlink(missing_ok=True)
    return [out / f"{n}{s}" for n in names for s in (".pem", ".key")]


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("out", type=Path, help="the folder to write (created)")
    parser.add_argument(
        "--master-address",
        action="append",
        default=[],
        help="an address or host name channels connect to (repeat; 127.0.0.1 and localhost "
        "are always added)",
    )
    parser.add_argument("--channels", default="", help="channel names, comma-separated")
    parser.add_argument("--days", type=int, default=3650, help="validity (default 3650)")
    args = parser.parse_args(argv)
    channels = [c for c in args.channels.split(",") if c]
    bad = [c for c in channels if NAME.fullmatch(c) is None or c in ("ca", "master")]
    if bad:
        parser.error(f"--channels: {bad[0]!r} is not a channel name (lowercase, digits, _ -)")
    if shutil.which("openssl") is None:
        print("dome_certs: error: openssl is not installed (apt install openssl)", file=sys.stderr)
        return 1
    addresses = [*dict.fromkeys([*args.master_address, "127.0.0.1", "localhost"])]
    try:
        files = generate(args.out, addresses, channels, args.days)
    except (FileExistsError, subprocess.CalledProcessError) as exc:
        detail = getattr(exc, "stderr", "") or str(exc)
        print(f"dome_certs: error: {detail.strip().splitlines()[-1]}", file=sys.stderr)
        return 1
    for f in files:
        print(f)
    return 0


if __name__ == "__main__":
    sys.exit(main())
