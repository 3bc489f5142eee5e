"""GPS truth: NMEA and CSV readers against hand-written logs, and the track in the site frame."""

from __future__ import annotations

import calendar
import datetime as dt
import math
from functools import reduce
from operator import xor
from pathlib import Path

import numpy as np
import pytest

from wz_drivers.gps import KNOT_MPS, gps_track, read_gps, read_gps_csv, read_nmea
from wz_drivers.records import FieldDataError, GpsFix, Problems
from wz_shared.site import DEFAULT_SITE_PATH, Site, load_site

DAY = dt.date(2025, 6, 23)


def sentence(body: str) -> str:
    """``$body*hh`` with the checksum computed here (XOR of the body's bytes)."""
    return f"${body}*{reduce(xor, body.encode('ascii'), 0):02X}"


def gga(
    time: str,
    *,
    quality: int = 4,
    talker: str = "GP",
    lat: str = "4045.0000",
    lon: str = "09641.2800",
) -> str:
    return sentence(f"{talker}GGA,{time},{lat},N,{lon},W,{quality},12,0.8,365.0,M,-27.0,M,1.0,0")


def rmc(
    time: str,
    date: str = "230625",
    *,
    speed_kn: str = "48.6",
    course: str = "0.5",
    status: str = "A",
) -> str:
    return sentence(
        f"GNRMC,{time},{status},4045.0000,N,09641.2800,W,{speed_kn},{course},{date},,,D"
    )


def vtg(course: str, speed_kn: str) -> str:
    return sentence(f"GPVTG,{course},T,,M,{speed_kn},N,{float(speed_kn) * 1.852:.3f},K,D")


def unix(day: dt.date, time_of_day_s: float) -> float:
    return calendar.timegm(day.timetuple()) + time_of_day_s


def write(tmp_path: Path, name: str, lines: list[str]) -> Path:
    path = tmp_path / name
    path.write_text("\r\n".join(lines) + "\r\n", encoding="ascii")
    return path


@pytest.fixture(scope="module")
def site() -> Site:
    return load_site(DEFAULT_SITE_PATH)


# --- NMEA -----------------------------------------------------------------------------------


def test_nmea_epochs_merge_gga_rmc_vtg_and_report_bad_checksum_and_no_fix(tmp_path: Path) -> None:
    bad = gga("120000.20")
    bad = bad[:-2] + ("00" if bad[-2:] != "00" else "11")
    lines = [
        gga("120000.00"),  # line 1
        rmc("120000.00"),
        vtg("0.5", "48.6"),
        sentence("GPGSV,3,1,11,03,03,111,00,04,15,270,00,06,01,010,00,13,06,292,00"),  # unused
        gga("120000.10", talker="GN"),
        rmc("120000.10", speed_kn="50.0", course="359.0"),
        bad,  # line 7: bad checksum
        rmc("120000.20"),
        gga("120000.30", quality=0, lat="", lon=""),  # line 9: no fix
        rmc("120000.30"),
        gga("120000.40"),
        vtg("10.0", "20.0"),  # no RMC: speed and course from VTG
    ]
    problems = Problems()
    fixes = list(read_nmea(write(tmp_path, "van.nmea", lines), problems))

    assert [f.stamp for f in fixes] == pytest.approx(
        [unix(DAY, 43200.0 + k) for k in (0.0, 0.1, 0.2, 0.4)], abs=1e-6
    )
    first = fixes[0]
    assert first.latitude_deg == pytest.approx(40.75)
    assert first.longitude_deg == pytest.approx(-(96 + 41.28 / 60))
    assert first.altitude_m == pytest.approx(365.0 - 27.0)  # ellipsoid height
    assert first.quality == 4
    assert first.speed_mps == pytest.approx(48.6 * KNOT_MPS)
    assert first.heading_deg == pytest.approx(0.5)
    assert fixes[1].speed_mps == pytest.approx(50.0 * 1852 / 3600)  # RMC preferred to VTG
    assert fixes[1].heading_deg == pytest.approx(359.0)
    assert fixes[2].quality is None and fixes[2].speed_mps is not None  # RMC alone: a fix
    assert fixes[3].speed_mps == pytest.approx(20.0 * KNOT_MPS)
    assert fixes[3].heading_deg == pytest.approx(10.0)

    assert [(e.line, e.path) for e in problems.errors] == [
        (7, str(tmp_path / "van.nmea")),
        (9, str(tmp_path / "van.nmea")),
    ]
    assert "checksum" in problems.errors[0].reason
    assert "quality 0" in problems.errors[1].reason
    assert str(problems.errors[0]).startswith(f"{tmp_path / 'van.nmea'}:7: ")


def test_nmea_midnight_rollover_in_gga_only_stretch(tmp_path: Path) -> None:
    lines = [
        gga("235959.80"),
        rmc("235959.80"),
        gga("235959.90"),
        gga("000000.00"),
        gga("000000.10"),
        rmc("000000.10", date="240625"),
    ]
    problems = Problems()
    stamps = [f.stamp for f in read_nmea(write(tmp_path, "night.nmea", lines), problems)]
    assert not problems.errors
    assert stamps == pytest.approx([unix(DAY, 86399.8 + 0.1 * k) for k in range(4)], abs=1e-6)


def test_nmea_date_before_first_rmc_from_argument_or_dated_back(tmp_path: Path) -> None:
    lines = [gga("235959.90"), gga("000000.00"), rmc("000000.00", date="240625")]
    path = write(tmp_path, "late.nmea", lines)
    expected = [unix(DAY, 86399.9), unix(DAY, 86400.0)]
    dated_back = [f.stamp for f in read_nmea(path, Problems())]
    assert dated_back == pytest.approx(expected, abs=1e-6)
    given = [f.stamp for f in read_nmea(path, Problems(), date=DAY)]
    assert given == pytest.approx(expected, abs=1e-6)


def test_nmea_without_any_date_reports_every_fix(tmp_path: Path) -> None:
    problems = Problems()
    path = write(tmp_path, "gga_only.nmea", [gga("120000.00"), gga("120000.10")])
    assert list(read_nmea(path, problems)) == []
    assert [e.line for e in problems.errors] == [1, 2]
    assert "date=" in problems.errors[0].reason
    assert len(list(read_nmea(path, Problems(), date=DAY))) == 2


def test_nmea_time_going_back_is_reported_and_skipped(tmp_path: Path) -> None:
    lines = [
        gga("120000.00"),
        rmc("120000.00"),
        gga("120000.10"),
        gga("120000.05"),
        gga("120000.20"),
    ]
    problems = Problems()
    fixes = list(read_nmea(write(tmp_path, "back.nmea", lines), problems))
    assert [round(f.stamp - unix(DAY, 43200.0), 3) for f in fixes] == [0.0, 0.1, 0.2]
    ((error),) = problems.errors
    assert error.line == 4 and "time goes back" in error.reason


def test_nmea_garbage_lines_and_missing_file(tmp_path: Path) -> None:
    lines = [
        gga("120000.00"),
        rmc("120000.00"),
        "#INSPVAXA,COM1,0,73.5,FINESTEERING",
        "$GPGGA,120000.10,4045.0000,N",
        gga("120000.20"),
    ]
    problems = Problems()
    fixes = list(read_nmea(write(tmp_path, "mixed.log", lines), problems))
    assert len(fixes) == 2
    assert [e.line for e in problems.errors] == [3, 4]
    with pytest.raises(FieldDataError, match="no such file"):
        read_nmea(tmp_path / "absent.nmea", Problems())


# --- CSV --------------------------------------------------------------------------------------


def test_csv_missing_columns_raise_naming_line_1_and_accepted_names(tmp_path: Path) -> None:
    path = tmp_path / "van.csv"
    path.write_text("time,latitude,longitude_deg\n1750680000.0,40.75,-96.688\n")
    with pytest.raises(FieldDataError) as raised:
        read_gps_csv(path, Problems())
    error = raised.value
    assert error.line == 1 and error.path == str(path)
    assert "latitude_deg" in error.reason and "(or lat)" in error.reason
    assert "longitude_deg" not in error.reason.split(";")[0]  # present, so not missing
    assert str(error).startswith(f"{path}:1: ")


def test_csv_rows_read_with_aliases_and_bad_rows_skipped(tmp_path: Path) -> None:
    path = tmp_path / "van.csv"
    path.write_text(
        "Time,Lat,Lon,speed_mps,heading_deg,quality,note\n"
        "1750680000.0,40.75,-96.688,25.0,0.5,4,ok\n"
        "1750680000.1,forty,-96.688,25.0,0.5,4,bad latitude\n"  # line 3
        "1750680000.2,40.75,-96.688,,,,unknowns\n"
        "1750680000.3,40.75,-96.688,25.0,0.5,0,no fix\n"  # line 5
        "1750680000.1,40.75,-96.688,25.0,0.5,4,back in time\n"  # line 6
        "2025-06-23T12:00:00.5Z,40.75,-96.688,25.0,0.5,4,iso time\n"
        "1750680000.6,40.75\n"  # line 8: short row
    )
    problems = Problems()
    fixes = list(read_gps_csv(path, problems))
    assert [f.stamp for f in fixes] == pytest.approx(
        [1750680000.0, 1750680000.2, unix(DAY, 43200.5)]
    )
    assert fixes[0] == GpsFix(1750680000.0, 40.75, -96.688, None, 25.0, 0.5, 4)
    assert fixes[1].speed_mps is None and fixes[1].quality is None
    assert [e.line for e in problems.errors] == [3, 5, 6, 8]


def test_read_gps_chooses_by_content(tmp_path: Path) -> None:
    nmea = write(tmp_path, "van.txt", [gga("120000.00"), rmc("120000.00")])
    assert len(list(read_gps(nmea, Problems()))) == 1
    table = tmp_path / "van.dat"
    table.write_text("time_unix_s,latitude_deg,longitude_deg\n1750680000.0,40.75,-96.688\n")
    assert len(list(read_gps(table, Problems()))) == 1
    other = tmp_path / "photo.txt"
    other.write_text("not a GPS log\n")
    with pytest.raises(FieldDataError, match="missing column"):
        read_gps(other, Problems())
    with pytest.raises(FieldDataError, match="no such file"):
        read_gps(tmp_path / "absent.csv", Problems())


# --- the track ------------------------------------------------------------------------------


def test_fix_at_site_origin_maps_to_zero(site: Site) -> None:
    origin = site.origin
    track = gps_track(
        [GpsFix(1.0, origin.latitude_deg, origin.longitude_deg, origin.altitude_m)], site
    )
    assert track.x_m[0] == pytest.approx(0.0, abs=1e-6)
    assert track.y_m[0] == pytest.approx(0.0, abs=1e-6)
    assert track.station_m[0] == pytest.approx(0.0, abs=1e-6)
    assert track.offset_m[0] == pytest.approx(0.0, abs=1e-6)
    assert track.heading_rad[0] == pytest.approx(math.pi / 2)  # the road's: northbound


def _northbound_fixes(
    site: Site, *, forward_m: float, left_m: float, with_course: bool
) -> list[GpsFix]:
    """A vehicle whose reference point drives north along x = 1.75 m at 25 m/s from y = 100 m;
    the antenna ``forward_m`` ahead and ``left_m`` to its left (left of north is west)."""
    t = np.arange(0.0, 4.0, 0.1)
    x = 1.75 - left_m + 0.0 * t
    y = 100.0 + 25.0 * t + forward_m
    latitude, longitude, altitude = site.geo_frame.to_wgs84(x, y, 0.0)
    return [
        GpsFix(
            1750680000.0 + float(tk),
            float(la),
            float(lo),
            float(al),
            25.0 if with_course else None,
            0.0 if with_course else None,
            4,
        )
        for tk, la, lo, al in zip(t, latitude, longitude, altitude, strict=True)
    ]


@pytest.mark.parametrize("with_course", [True, False])
def test_antenna_offset_is_removed(site: Site, with_course: bool) -> None:
    fixes = _northbound_fixes(site, forward_m=1.0, left_m=0.5, with_course=with_course)
    track = gps_track(fixes, site, antenna_forward_m=1.0, antenna_left_m=0.5)
    t = track.t - track.t[0]
    np.testing.assert_allclose(track.y_m, 100.0 + 25.0 * t, atol=1e-6)
    np.testing.assert_allclose(track.x_m, 1.75, atol=1e-6)
    np.testing.assert_allclose(track.heading_rad, math.pi / 2, atol=1e-9)
    np.testing.assert_allclose(track.station_m, 100.0 + 25.0 * t, atol=1e-6)
    np.testing.assert_allclose(track.offset_m, -1.75, atol=1e-6)  # east of north: right
    # Given, or differentiated: Unix stamps near 1.75e9 s are rounded to 2.4e-7 s.
    np.testing.assert_allclose(track.speed_mps, 25.0, atol=1e-4)


def test_stopped_vehicle_takes_the_roads_heading_and_fixes_must_increase(site: Site) -> None:
    fixes = _northbound_fixes(site, forward_m=1.0, left_m=0.0, with_course=False)
    still = [
        GpsFix(f.stamp, fixes[0].latitude_deg, fixes[0].longitude_deg, f.altitude_m)
        for f in fixes[:5]
    ]
    track = gps_track(still, site, antenna_forward_m=1.0)
    np.testing.assert_allclose(track.heading_rad, math.pi / 2, atol=1e-9)
    np.testing.assert_allclose(track.y_m, 100.0, atol=1e-6)
    np.testing.assert_allclose(track.speed_mps, 0.0, atol=1e-6)
    with pytest.raises(ValueError, match="must increase"):
        gps_track([fixes[1], fixes[0]], site)
