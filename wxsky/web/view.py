"""What the page is shown (docs/web.md, `view`): the daemon's `status`, cut to what an
instructor reads, with the sun and moon, the ring's rebuilds and the METAR stations in use.
Pure: plain data in, plain data out."""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any

from wxsky.weather.stations import weights

# Status keys the page shows as they are.
_KEPT = ("fps", "frames_published", "weather", "target", "settled", "overrides", "channel")
_INPUT_KEYS = ("name", "kind", "ok", "messages", "errors", "last_error", "last_message_s")


def page_view(
    status: Mapping[str, Any],
    sky: Mapping[str, Any],
    ring: Mapping[str, Any],
    stations: Sequence[Mapping[str, Any]],
    clients: int,
) -> dict[str, Any]:
    """The `view` message from the daemon's `status`, its sky (`SkyParams.to_dict`), the
    ring's `{"version", "busy", "rebuilds"}` and the stations (`station_rows`)."""
    view: dict[str, Any] = {"type": "view"}
    for key in _KEPT:
        view[key] = status.get(key)
    frames = status.get("frames") or {}
    gap_s = frames.get("recent_largest_gap_s")
    view["frame_gap_ms"] = None if gap_s is None else 1000.0 * float(gap_s)
    view["ring"] = dict(ring)
    weather = status.get("weather") or {}
    view["clock"] = {
        "time_utc": weather.get("time_utc"),
        "rate": status.get("clock_rate"),
        "frozen": bool(status.get("frozen", False)),
        "at_end": bool(status.get("clock_at_end", False)),
    }
    view["sun"] = {
        "elevation_deg": sky.get("sun_elevation_deg"),
        "azimuth_deg": sky.get("sun_azimuth_deg"),
    }
    view["moon"] = {
        "elevation_deg": sky.get("moon_elevation_deg"),
        "azimuth_deg": sky.get("moon_azimuth_deg"),
        "illuminated": sky.get("moon_illuminated_fraction"),
    }
    view["inputs"] = [{k: row.get(k) for k in _INPUT_KEYS} for row in status.get("inputs") or ()]
    view["stations"] = list(stations)
    grib = status.get("grib")
    view["model"] = (
        None
        if not isinstance(grib, Mapping)
        else {k: grib.get(k) for k in ("steps_utc", "metar_weight", "reason", "sources")}
    )
    view["clients"] = clients
    return view


def station_rows(
    chosen: Sequence[tuple[str, float, float, float, str | None]],
) -> list[dict[str, Any]]:
    """The stations the METAR weather is made of, each (id, lat, lon, distance_m,
    observed_utc), nearest first, with its share of the blend (`weather.stations.weights`)."""
    shares = weights([d for _, _, _, d, _ in chosen])
    return [
        {
            "station": sid,
            "lat_deg": lat,
            "lon_deg": lon,
            "distance_km": d / 1000.0,
            "weight": w,
            "observed_utc": observed,
        }
        for (sid, lat, lon, d, observed), w in zip(chosen, shares, strict=True)
    ]
