"""One plausible packet of every CIGI type in the table, and the messages they make: the
seeds of the fuzz target, the round trips of the tests and what a test host sends.

Values are chosen to exercise the table: bit fields set beside each other, f32 values that
are not exact in f32, wrapped angles, a date that needs its leading zero.
"""

from __future__ import annotations

from wxsky.protocols.cigi import Packet, make
from wxsky.protocols.cigi_packets import PACKETS


def examples() -> dict[str, Packet]:
    """Table key -> an example packet, in table order."""
    made = [
        make(
            "ig_control",
            database_number=3,
            ig_mode=1,
            timestamp_valid=1,
            smoothing_enable=1,
            host_frame_number=120_001,
            timestamp_10us=4_000_123,
            last_ig_frame_number=119_998,
        ),
        make(
            "entity_control",
            entity_id=0,
            entity_state=1,
            ground_clamp=2,
            animation_state=2,
            smoothing_enable=1,
            alpha=255,
            entity_type=1001,
            roll_deg=-12.5,
            pitch_deg=3.25,
            yaw_deg=-90.0,  # a ±180 host's west: kept as 270
            lat_deg=47.4502,
            lon_deg=-122.3088,
            alt_m=1520.4,
        ),
        make(
            "celestial_sphere_control",
            hour=13,
            minute=43,
            ephemeris_enable=1,
            sun_enable=1,
            moon_enable=1,
            star_field_enable=1,
            date_time_valid=1,
            date_mmddyyyy=6_12_1987,  # 12 June 1987
            star_field_intensity_pct=80.0,
        ),
        make(
            "atmosphere_control",
            atmospheric_model_enable=1,
            humidity_pct=65,
            temperature_c=14.2,
            visibility_m=24_000.0,
            wind_speed_mps=6.1,
            vertical_wind_speed_mps=-0.2,
            wind_dir_deg=250.0,
            pressure_hpa=1013.25,
        ),
        make(
            "environmental_region_control",
            region_id=7,
            region_state=1,
            merge_weather=1,
            merge_terrestrial=1,
            lat_deg=47.5,
            lon_deg=-122.25,
            size_x_m=20_000.0,
            size_y_m=15_000.0,
            corner_radius_m=2000.0,
            rotation_deg=-30.0,
            transition_perimeter_m=1500.0,
        ),
        make(
            "weather_control",
            entity_or_region_id=0,
            layer_id=1,
            humidity_pct=80,
            weather_enable=1,
            random_winds_enable=1,
            cloud_type=9,  # stratocumulus
            scope=0,
            severity=2,
            temperature_c=8.5,
            visibility_m=9999.0,
            scud_frequency_pct=10.0,
            coverage_pct=62.5,
            base_elevation_m=1219.2,
            thickness_m=600.0,
            transition_band_m=100.0,
            wind_speed_mps=12.86,
            vertical_wind_speed_mps=0.5,
            wind_dir_deg=-100.0,  # CCL's -180..180: kept as 260
            pressure_hpa=1009.0,
            aerosol_concentration_gpm3=0.25,
        ),
        make(
            "view_control",
            view_id=1,
            group_id=2,
            x_enable=1,
            y_enable=1,
            z_enable=1,
            pitch_enable=1,
            yaw_enable=1,
            entity_id=0,
            x_offset_m=0.5,
            y_offset_m=-0.3,
            z_offset_m=1.1,
            pitch_deg=-5.0,
            yaw_deg=350.0,
        ),
        make(
            "view_definition",
            view_id=1,
            group_id=2,
            near_enable=1,
            far_enable=1,
            left_enable=1,
            right_enable=1,
            top_enable=1,
            bottom_enable=1,
            mirror_mode=1,
            reorder=1,
            view_type=2,
            near_m=0.1,
            far_m=100_000.0,
            left_deg=-30.0,
            right_deg=30.0,
            top_deg=20.0,
            bottom_deg=-20.0,
        ),
        make(
            "environmental_conditions_request",
            request_weather=1,
            request_aerosol=1,
            request_id=42,
            lat_deg=47.4502,
            lon_deg=-122.3088,
            alt_m=3048.0,
        ),
        make(
            "start_of_frame",
            database_number=3,
            ig_status=0,
            ig_mode=1,
            timestamp_valid=1,
            ig_frame_number=119_999,
            timestamp_10us=3_999_456,
            last_host_frame_number=120_001,
        ),
        make(
            "weather_conditions_response",
            request_id=42,
            humidity_pct=71,
            temperature_c=-4.6,
            visibility_m=8000.0,
            wind_speed_mps=15.3,
            vertical_wind_speed_mps=0.0,
            wind_dir_deg=275.5,
            pressure_hpa=700.1,
        ),
        make(
            "aerosol_concentration_response",
            request_id=42,
            layer_id=1,
            aerosol_concentration_gpm3=0.4,
        ),
    ]
    by_key = {p.key: p for p in made}
    return {spec.key: by_key[spec.key] for spec in PACKETS}


def messages() -> list[list[Packet]]:
    """Messages as a sender makes them: each packet behind its direction's first packet,
    then every packet of a direction together, then repeats (one aerosol packet a layer)."""
    ex = examples()
    host, ig = ex["ig_control"], ex["start_of_frame"]
    host_body = [p for p in ex.values() if p.spec.direction == "host_to_ig" and p is not host]
    ig_body = [p for p in ex.values() if p.spec.direction == "ig_to_host" and p is not ig]
    singles = [[host, p] for p in host_body] + [[ig, p] for p in ig_body]
    aerosol = ex["aerosol_concentration_response"]
    return [
        [host],
        [ig],
        *singles,
        [host, *host_body],
        [ig, *ig_body],
        [ig, ex["weather_conditions_response"], aerosol, aerosol, aerosol],
        [host, ex["weather_control"], ex["weather_control"], ex["atmosphere_control"]],
    ]
