"""Road frame and WGS84 frame: closed forms, round trips, cross-checks, speed."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import HealthCheck, assume, given, settings
from hypothesis import strategies as st
from pyproj import Geod

from wz_shared.arrays import F64
from wz_shared.geometry import GRID_REACH_M, GeoFrame, RoadFrame
from wz_shared.site import DEFAULT_SITE_PATH, load_site

ROUNDTRIP_TOLERANCE_M = 1e-3
PROPERTY = settings(
    derandomize=True, max_examples=200, deadline=None, suppress_health_check=[HealthCheck.too_slow]
)

DEFAULT_FRAME = load_site(DEFAULT_SITE_PATH).road_frame


# --- helpers ---------------------------------------------------------------------------------


def arc_polyline(radius_m: float, spacing_m: float, angle_rad: float, turn: int) -> F64:
    """Vertices on a circle of ``radius_m``, starting at (0, 0) heading north (+y).

    ``turn`` +1 turns left (centre at (-R, 0)), -1 turns right (centre at (+R, 0)); the vertex
    at polar angle phi (from the start, about the centre) is R (cos phi, sin phi) mirrored.
    """
    count = math.ceil(angle_rad * radius_m / spacing_m)
    phi = np.linspace(0.0, angle_rad, count + 1)
    return np.column_stack([turn * radius_m * (np.cos(phi) - 1.0), radius_m * np.sin(phi)])


def polar_about_arc_centre(radius_m: float, turn: int, r_m: F64, phi: F64) -> tuple[F64, F64]:
    """Site position of the point at distance r and angle phi (from the start) about the centre."""
    return turn * (r_m * np.cos(phi) - radius_m), r_m * np.sin(phi)


@st.composite
def smooth_centerlines(draw: st.DrawFn) -> F64:
    """Random smooth roads: |curvature| <= 1 / (100 m), vertex spacing 5..25 m, length 150..700 m.

    The curvature is a sum of three sinusoids; the heading may wander by at most 2.5 rad so that
    the road cannot come back near itself (two points far apart along it stay far apart).
    """
    length = draw(st.floats(150.0, 700.0))
    spacing = draw(st.floats(5.0, 25.0))
    heading0 = draw(st.floats(-math.pi, math.pi))
    start = np.array([draw(st.floats(-500.0, 500.0)), draw(st.floats(-500.0, 500.0))])
    amplitude = np.array([draw(st.floats(-1.0, 1.0)) for _ in range(3)])
    phase = np.array([draw(st.floats(0.0, 2 * math.pi)) for _ in range(3)])
    wavenumber = 2 * math.pi * np.arange(1, 4) / length
    step = 0.05
    s = np.arange(0.0, length + step, step)
    curvature = np.sum(
        amplitude[:, None] * np.sin(wavenumber[:, None] * s + phase[:, None]), axis=0
    ) / (3 * 100.0)
    heading = (
        heading0 + np.concatenate([[0.0], np.cumsum(0.5 * (curvature[1:] + curvature[:-1]))]) * step
    )
    assume(np.ptp(heading) <= 2.5)
    xy = start + np.column_stack(
        [
            np.concatenate([[0.0], np.cumsum(np.cos(heading[:-1]) * step)]),
            np.concatenate([[0.0], np.cumsum(np.sin(heading[:-1]) * step)]),
        ]
    )
    stride = max(1, round(spacing / step))
    vertices: F64 = xy[::stride]
    return vertices


# --- straight centerline: closed forms -------------------------------------------------------


def test_straight_centerline_matches_dot_and_cross_products() -> None:
    heading = math.radians(30.0)
    tangent = np.array([math.cos(heading), math.sin(heading)])
    origin = np.array([12.0, -7.0])
    # Uneven vertex spacing, all on one line.
    along = np.array([0.0, 10.0, 35.0, 36.5, 80.0, 200.0])
    frame = RoadFrame(origin + along[:, None] * tangent)
    rng = np.random.default_rng(1)
    # Beyond both ends and beyond the grid's reach too (exhaustive search).
    q = origin + rng.uniform(-150.0, 350.0, (2000, 2))
    station, offset = frame.to_road(q[:, 0], q[:, 1])
    w = q - origin
    np.testing.assert_allclose(station, w @ tangent, rtol=0, atol=1e-9)
    np.testing.assert_allclose(
        offset, tangent[0] * w[:, 1] - tangent[1] * w[:, 0], rtol=0, atol=1e-9
    )
    np.testing.assert_allclose(frame.heading_at(station), heading, rtol=0, atol=1e-12)
    assert frame.length_m == pytest.approx(200.0, abs=1e-12)


def test_offset_is_positive_to_the_left() -> None:
    frame = RoadFrame([[0.0, 0.0], [0.0, 100.0]])  # heading north: left is west (-x)
    station, offset = frame.to_road(-2.0, 40.0)
    assert (float(station), float(offset)) == pytest.approx((40.0, 2.0))
    x, y = frame.to_site(40.0, 2.0)
    assert (float(x), float(y)) == pytest.approx((-2.0, 40.0))


# --- curved centerline: closed forms within the chord tolerance ------------------------------


@pytest.mark.parametrize("turn", [1, -1], ids=["left", "right"])
@pytest.mark.parametrize("spacing_m", [10.0, 25.0])
def test_arc_station_and_offset_match_polar_coordinates(turn: int, spacing_m: float) -> None:
    """On an arc of radius R: s = R phi and d = turn (R - r), to the polyline's chord tolerance.

    The polyline's chords lie inside the arc by at most the sagitta R (1 - cos(dphi / 2)), about
    L^2 / (8 R) (dphi = L / R), so |d - turn (R - r)| <= sagitta: 4 cm at R = 300 m, L = 10 m,
    26 cm at L = 25 m. Each chord is shorter than its arc by
    R dphi - 2 R sin(dphi / 2) <= R dphi^3 / 24, so after n whole chords and part
    of one |s - R phi| <= (n + 1) R dphi^3 / 24. Offsets are radial, so s does not depend on d.
    The first and last segments are left out: there the normal is the segment's own, as the
    polyline says nothing of the curve beyond its ends.
    """
    radius = 300.0
    vertices = arc_polyline(radius, spacing_m, math.pi / 2, turn)
    frame = RoadFrame(vertices)
    step = math.pi / 2 / (len(vertices) - 1)
    chord = 2 * radius * math.sin(step / 2)
    sagitta = radius * (1 - math.cos(step / 2))
    rng = np.random.default_rng(2)
    phi = rng.uniform(step, math.pi / 2 - step, 5000)
    r = radius + rng.uniform(-30.0, 30.0, phi.size)
    x, y = polar_about_arc_centre(radius, turn, r, phi)
    station, offset = frame.to_road(x, y)
    station_tolerance = (phi / step + 1) * radius * step**3 / 24
    assert np.all(np.abs(station - radius * phi) <= station_tolerance)
    assert np.all(np.abs(offset - turn * (radius - r)) <= sagitta + 1e-9)
    # At the vertices the polyline is on the arc: exact offset and arc tangent heading.
    vertex_phi = np.arange(1, len(vertices) - 1, dtype=np.float64) * step
    x, y = polar_about_arc_centre(radius, turn, np.full(vertex_phi.size, radius - 10.0), vertex_phi)
    station, offset = frame.to_road(x, y)
    np.testing.assert_allclose(offset, turn * 10.0, rtol=0, atol=1e-9)
    np.testing.assert_allclose(station, np.arange(1, len(vertices) - 1) * chord, rtol=0, atol=1e-9)
    np.testing.assert_allclose(
        frame.heading_at(station), math.pi / 2 + turn * vertex_phi, atol=1e-12
    )


def test_heading_is_continuous_through_vertices() -> None:
    frame = RoadFrame(arc_polyline(100.0, 25.0, math.pi / 2, 1))
    inner = frame.vertex_stations_m[1:-1]
    before = frame.heading_at(inner - 1e-9)
    after = frame.heading_at(inner + 1e-9)
    np.testing.assert_allclose(before, after, atol=1e-9)


def test_mapping_is_continuous_across_vertices_on_a_curve() -> None:
    """Where nearest-segment projection jumps (outside a vertex), this frame does not."""
    frame = RoadFrame(arc_polyline(100.0, 25.0, math.pi / 2, 1))
    vertex = frame.vertex_stations_m[2]
    station = vertex + np.linspace(-1e-6, 1e-6, 11)
    for offset in (-30.0, 30.0):
        x, y = frame.to_site(station, np.full(station.size, offset))
        gaps = np.hypot(np.diff(x), np.diff(y))
        assert np.all(gaps < 1e-6)


# --- round trips ---------------------------------------------------------------------------


@PROPERTY
@given(
    station=st.floats(-20.0, DEFAULT_FRAME.length_m + 20.0),
    offset=st.floats(-30.0, 30.0),
)
def test_default_site_road_site_road_roundtrip(station: float, offset: float) -> None:
    x, y = DEFAULT_FRAME.to_site(station, offset)
    station_back, offset_back = DEFAULT_FRAME.to_road(x, y)
    assert abs(float(station_back) - station) < ROUNDTRIP_TOLERANCE_M
    assert abs(float(offset_back) - offset) < ROUNDTRIP_TOLERANCE_M


@PROPERTY
@given(x=st.floats(-40.0, 160.0), y=st.floats(-40.0, 2030.0))
def test_default_site_site_road_site_roundtrip(x: float, y: float) -> None:
    station, offset = DEFAULT_FRAME.to_road(x, y)
    assume(abs(float(offset)) <= 30.0)
    x_back, y_back = DEFAULT_FRAME.to_site(station, offset)
    assert math.hypot(float(x_back) - x, float(y_back) - y) < ROUNDTRIP_TOLERANCE_M


@PROPERTY
@given(vertices=smooth_centerlines(), seed=st.integers(0, 2**32 - 1))
def test_smooth_curve_roundtrips(vertices: F64, seed: int) -> None:
    frame = RoadFrame(vertices)
    rng = np.random.default_rng(seed)
    station = rng.uniform(-20.0, frame.length_m + 20.0, 500)
    offset = rng.uniform(-30.0, 30.0, 500)
    x, y = frame.to_site(station, offset)
    station_back, offset_back = frame.to_road(x, y)
    assert np.max(np.abs(station_back - station)) < ROUNDTRIP_TOLERANCE_M
    assert np.max(np.abs(offset_back - offset)) < ROUNDTRIP_TOLERANCE_M
    # Arbitrary points near the road: site -> road -> site.
    q = np.column_stack([x, y]) + rng.uniform(-15.0, 15.0, (500, 2))
    station, offset = frame.to_road(q[:, 0], q[:, 1])
    near = np.abs(offset) <= 30.0
    x_back, y_back = frame.to_site(station[near], offset[near])
    assert np.max(np.hypot(x_back - q[near, 0], y_back - q[near, 1])) < ROUNDTRIP_TOLERANCE_M


@pytest.mark.parametrize("turn", [1, -1], ids=["left", "right"])
def test_tightest_curve_roundtrips(turn: int) -> None:
    """Radius 100 m, 25 m between vertices (a 14 deg turn at each), |d| up to 30 m."""
    frame = RoadFrame(arc_polyline(100.0, 25.0, 2.5, turn))
    rng = np.random.default_rng(7)
    station = rng.uniform(-20.0, frame.length_m + 20.0, 20_000)
    offset = rng.uniform(-30.0, 30.0, station.size)
    x, y = frame.to_site(station, offset)
    station_back, offset_back = frame.to_road(x, y)
    assert np.max(np.abs(station_back - station)) < 1e-6
    assert np.max(np.abs(offset_back - offset)) < 1e-6


def test_default_site_roundtrip_batch() -> None:
    rng = np.random.default_rng(3)
    station = rng.uniform(-50.0, DEFAULT_FRAME.length_m + 50.0, 20_000)
    offset = rng.uniform(-30.0, 30.0, station.size)
    x, y = DEFAULT_FRAME.to_site(station, offset)
    station_back, offset_back = DEFAULT_FRAME.to_road(x, y)
    x_back, y_back = DEFAULT_FRAME.to_site(station_back, offset_back)
    assert np.max(np.abs(station_back - station)) < 1e-6
    assert np.max(np.abs(offset_back - offset)) < 1e-6
    assert np.max(np.hypot(x_back - x, y_back - y)) < 1e-6


def test_extrapolates_beyond_the_ends() -> None:
    # The default site starts with a straight run north from the origin.
    station, offset = DEFAULT_FRAME.to_road(3.0, -50.0)
    assert (float(station), float(offset)) == pytest.approx((-50.0, -3.0), abs=1e-9)
    end = DEFAULT_FRAME.length_m
    x, y = DEFAULT_FRAME.to_site(end + 40.0, 2.0)
    station, offset = DEFAULT_FRAME.to_road(x, y)
    assert (float(station), float(offset)) == pytest.approx((end + 40.0, 2.0), abs=1e-9)
    heading = DEFAULT_FRAME.heading_at([end, end + 40.0])
    assert heading[0] == pytest.approx(heading[1], abs=1e-12)


# --- the two searches agree; far points ------------------------------------------------------


def test_grid_search_agrees_with_exhaustive_search() -> None:
    """The fast grid search and the exhaustive search are two implementations of one rule."""
    frame = RoadFrame(arc_polyline(150.0, 20.0, 2.0, -1))
    rng = np.random.default_rng(4)
    station = rng.uniform(-30.0, frame.length_m + 30.0, 5000)
    offset = rng.uniform(-GRID_REACH_M, GRID_REACH_M, station.size)
    x, y = frame.to_site(station, offset)
    fast = frame.to_road(x, y)
    reference = frame._to_road_exhaustive(x, y)  # the reference implementation
    np.testing.assert_allclose(fast[0], reference[0], rtol=0, atol=1e-9)
    np.testing.assert_allclose(fast[1], reference[1], rtol=0, atol=1e-9)


def test_far_points_are_finite_and_roundtrip_on_the_outside() -> None:
    frame = RoadFrame(arc_polyline(300.0, 25.0, math.pi / 2, 1))
    rng = np.random.default_rng(5)
    station = rng.uniform(0.0, frame.length_m, 1000)
    offset = rng.uniform(-250.0, -50.0, station.size)  # outside a left turn: the fan opens
    x, y = frame.to_site(station, offset)
    station_back, offset_back = frame.to_road(x, y)
    np.testing.assert_allclose(station_back, station, rtol=0, atol=1e-6)
    np.testing.assert_allclose(offset_back, offset, rtol=0, atol=1e-6)
    # Anywhere at all, even near the centre of the curve: finite values, never NaN.
    q = rng.uniform(-1000.0, 1000.0, (1000, 2))
    assert np.all(np.isfinite(frame.to_road(q[:, 0], q[:, 1])))


# --- shapes, errors, speed -------------------------------------------------------------------


def test_scalars_give_0d_arrays_and_arrays_broadcast() -> None:
    station, offset = DEFAULT_FRAME.to_road(1.0, 500.0)
    assert station.shape == () and offset.shape == ()
    x, y = DEFAULT_FRAME.to_site(np.zeros((3, 1)), np.zeros(4))
    assert x.shape == y.shape == (3, 4)
    station, offset = DEFAULT_FRAME.to_road(np.zeros((2, 5)), np.linspace(0, 100, 5))
    assert station.shape == offset.shape == (2, 5)
    assert DEFAULT_FRAME.heading_at(100.0).shape == ()
    assert DEFAULT_FRAME.tangent_at([1.0, 2.0]).shape == (2, 2)
    assert DEFAULT_FRAME.to_road(np.array([]), np.array([]))[0].shape == (0,)


@pytest.mark.parametrize(
    ("vertices", "message"),
    [
        ([[0.0, 0.0]], "N >= 2"),
        ([[0.0, 0.0], [0.0, 0.0], [1.0, 0.0]], "vertices 0 and 1 coincide"),
        ([[0.0, 0.0], [float("nan"), 1.0]], "finite"),
        ([[0.0, 0.0], [10.0, 0.0], [0.0, 0.5]], "turns by"),
    ],
)
def test_bad_centerlines_are_refused(vertices: list[list[float]], message: str) -> None:
    with pytest.raises(ValueError, match=message):
        RoadFrame(vertices)


# --- WGS84 -----------------------------------------------------------------------------------

SITE = load_site(DEFAULT_SITE_PATH)


def test_origin_maps_to_zero() -> None:
    geo = SITE.geo_frame
    origin = SITE.origin
    x, y, z = geo.to_site(origin.latitude_deg, origin.longitude_deg, origin.altitude_m)
    assert (float(x), float(y), float(z)) == pytest.approx((0.0, 0.0, 0.0), abs=1e-9)
    # By default a WGS84 point is taken at the origin's altitude.
    assert float(geo.to_site(origin.latitude_deg, origin.longitude_deg)[2]) == pytest.approx(
        0.0, abs=1e-9
    )
    lat, lon, alt = geo.to_wgs84(0.0, 0.0)
    assert (float(lat), float(lon)) == pytest.approx(
        (origin.latitude_deg, origin.longitude_deg), abs=1e-12
    )
    # Geocentric -> geodetic is iterative in PROJ: nanometres off.
    assert float(alt) == pytest.approx(origin.altitude_m, abs=1e-6)


@pytest.mark.parametrize(
    ("east", "north", "up"), [(1000.0, 0.0, 0.0), (0.0, 1000.0, 0.0), (1000.0, 1000.0, 12.0)]
)
def test_wgs84_roundtrip(east: float, north: float, up: float) -> None:
    geo = SITE.geo_frame
    lat, lon, alt = geo.to_wgs84(east, north, up)
    x, y, z = geo.to_site(lat, lon, alt)
    assert math.dist((float(x), float(y), float(z)), (east, north, up)) < 1e-3
    # North is north: latitude grows with y, longitude with x.
    assert (float(lat) > SITE.origin.latitude_deg) == (north > 0)
    assert (float(lon) > SITE.origin.longitude_deg) == (east > 0)


def test_wgs84_vectorised() -> None:
    geo = SITE.geo_frame
    x = np.linspace(-2000.0, 2000.0, 12).reshape(3, 4)
    lat, lon, alt = geo.to_wgs84(x, -x)
    assert lat.shape == lon.shape == alt.shape == (3, 4)
    x_back, y_back, z_back = geo.to_site(lat, lon, alt)
    np.testing.assert_allclose(x_back, x, atol=1e-6)
    np.testing.assert_allclose(y_back, -x, atol=1e-6)
    np.testing.assert_allclose(z_back, 0.0, atol=1e-6)


def test_distances_agree_with_the_geodesic() -> None:
    """The site frame is a rigid ENU frame, so site distances are true 3-D distances.

    Geod measures along the ellipsoid (height 0): points on the ellipsoid 2 km apart differ from
    their straight chord by about D^3 / (24 R^2) ~ 10 micrometres. The default site's origin is
    365 m up, so the points (on the ellipsoid) sit 365 m below its frame, and the 3-D distance
    is the one to compare; with an origin on the ellipsoid the horizontal distance agrees too.
    """
    geod = Geod(ellps="WGS84")
    lon1, lat1, _ = geod.fwd(SITE.origin.longitude_deg, SITE.origin.latitude_deg, 210.0, 900.0)
    lon2, lat2, _ = geod.fwd(lon1, lat1, 40.0, 2000.0)
    geodesic = geod.inv(lon1, lat1, lon2, lat2)[2]
    assert geodesic == pytest.approx(2000.0, abs=1e-6)
    a = np.array(SITE.geo_frame.to_site([lat1, lat2], [lon1, lon2], [0.0, 0.0]))
    assert np.linalg.norm(a[:, 1] - a[:, 0]) == pytest.approx(geodesic, abs=0.01)
    flat = GeoFrame(SITE.origin.latitude_deg, SITE.origin.longitude_deg, 0.0)
    b = np.array(flat.to_site([lat1, lat2], [lon1, lon2], [0.0, 0.0]))
    assert np.linalg.norm(b[:2, 1] - b[:2, 0]) == pytest.approx(geodesic, abs=0.01)
