"""What the METAR decoder tests share: the soundness check every decode must pass, real reports
that between them use every group kind, and the distinct reports of the fixture corpora."""

from __future__ import annotations

import json
import zlib
from functools import cache
from pathlib import Path

from wxsky.weather.feeds import read_feed
from wxsky.weather.metar import Metar
from wxsky.weather.metar_clouds import metar_to_patch
from wxsky.weather.state import WeatherState

DATA_DIR = Path(__file__).resolve().parent / "data" / "metar"


def assert_consistent(r: Metar) -> None:
    """The cheap part of assert_sound, for sweeps over hundreds of thousands of decodes."""
    assert r.partial == bool(r.errors)
    assert all(e and "\n" not in e and "\r" not in e for e in r.errors)
    assert r.time_utc is None or r.time_group is not None


def assert_sound(r: Metar) -> None:
    """What holds for every decode: errors explain partial, one line each, and the result
    serialises and makes a patch the weather state accepts."""
    assert_consistent(r)
    json.dumps(r.to_dict())
    r.describe()
    WeatherState().apply(metar_to_patch(r, field_elevation_m=1000.0))


REAL_REPORTS = [
    "KBDN 262135Z AUTO 36007KT 10SM CLR 16/03 A3008 RMK AO2",
    "UKHH 262130Z 01002MPS 6000 NSC 11/09 Q1018 070///65 NOSIG",
    "KSTF 231135Z AUTO 00000KT 1/2SM FG VV005 10/10 A3011 RMK AO2 VIS M1/4V3",
    "OPLA 272225Z 33006KT 4000 FU NSC 11/06 Q1011 NOSIG RMK QFE986 A29.88",
    "METAR KDTA 201520Z AUTO 07010KT 10SM CLR 13/M06 A3031 RMK AO1",
    "SPECI CYBW 201519Z AUTO 15006KT 1SM R35/2800V4000FT/ -RA BR VV002 00/00 A2978 RMK VIS VRB "
    "1/4-2 1/2 ICE PAST HR PRESFR SLP131",
    "EDNY 262125Z AUTO 02002KT 2500 0400/ R24/0900VP2000U BR NSC 09/08 Q1027",
    "PHBK 262119Z AUTO 29004KT 1 1/4SM +RA BR BKN007 OVC014 26/24 A3002 RMK AO2 P0024 T02560244",
    "KPCM 262115Z AUTO 09011G18KT 2SM +RA BKN007 OVC015 24/ A3000 RMK AO2 P0031",
    "SOCA 020030Z AUTO VRB02KT 4300 0900 R08/1200D +RA BCFG SCT025/// ///TCU 26/26 Q1014",
    "TFFR 262130Z 29006KT 250V020 7000 2000W -TSRA FEW003 SCT010 FEW013CB 24/23 Q1011 TEMPO 2000 "
    "TSRA",
    "MGMT 262100Z 18006KT 9999 FEW015 FEW025HVH422 262103 GG MUHAYMYX MYNNYMYX SAZZMAMX",
    # From here on, reports that bring group kinds the ones above lack (regional groups, the
    # second report glued on, QFE, a wind without its unit, a metre suffix).
    "ENQC 262120Z AUTO 24046KT 9999NDV BKN031/// 12/05 Q1007 W///S7",
    "EHJR 231125Z AUTO 14022KT //// // ///////// 16/14 Q1006 RE// W16/H11",
    "K1EM 261555Z AUTO 27012KT 10SM M 19/14 A3000",
    "LUKK 262130Z 34005KT 9999 FEW049 11/05 Q1017 R08/65D NOSIG",
    "EHGR 262129Z AUTO 28003KT 2700 BR OVC053 15/15 Q1026 YLO",
    "MGQZ 020000Z 05014KT 9999 SCT020 OVC090 17/10 QFE 774.6",
    "CWKP 231137Z AUTO 25017KT ////SM FEW012 BKN020 OVC026 M11/M13 A3001",
    "HSPN 231100Z 04014 9999 SCT030 32/23 Q1013",
    "YBBN 180755Z 23021KT 9000 TSRA FEW008 BKN045CB BKN100 28/19 Q1008 FM0900 35010KT 9999",
    "MHLE 262100Z 20006KT 9999 SCT022TCU SCT024CB 20/17 METAR ",
    "UIBB 262100Z 36003MPS P5000 FEW040CB M03/M06 Q1026 NOSIG RMK QFE726/0968",
    "MGTU 262100Z 09004 9999 SCT016 FEW022CB BKN080 31/26 CB/PCPN/ N/NNE",
    "CWRH 262100Z AUTO ///// M04/ A2970 RMK SLP091",
    "RJSN 262100Z 18005KT 9999 FEW050 SCT190 BKN/// 22/18 Q1010",
    "OPNH 262055Z 18008KT 4000M HZ NSC 27/20 Q1007",
]
# Composed, not real: groups that no fixture report has where the decoder meets them in the
# body (a NIL report, km visibility, wind shear, flags and a missing QNH after the body).
COMPOSED_REPORTS = [
    "KXYZ 261555Z NIL",
    "UUWW 262130Z 27004MPS 10KM BKN020 SCT030 CB 12/08 Q1015 WS R24 AUTO COR",
    "ZBAA 262130Z 04003MPS CAVOK 18/12 Q1013 Q//// RERA",
    "KAAA 261550Z 27010KT 10SM CLR 20/10 A3000 KBBB 261550Z 09050KT 1/4SM",
]


@cache
def corpus_reports() -> dict[str, tuple[int, int]]:
    """Every distinct report of the fixture corpora, with its feed's year and month."""
    reports: dict[str, tuple[int, int]] = {}
    for path in sorted(DATA_DIR.glob("*.gz")):
        for report in read_feed(path).reports:
            reports.setdefault(report.raw, (report.year, report.month))
    return reports


def gzip_bomb(unpacked_bytes: int) -> bytes:
    """gzip data that unpacks to `unpacked_bytes` zeros, packed a megabyte at a time (about
    0.1 s and 300 kB per 64 MiB)."""
    packer = zlib.compressobj(1, zlib.DEFLATED, 16 + zlib.MAX_WBITS)
    zeros = bytes(1024 * 1024)
    whole, rest = divmod(unpacked_bytes, len(zeros))
    parts = [packer.compress(zeros) for _ in range(whole)]
    return b"".join([*parts, packer.compress(zeros[:rest]), packer.flush()])
