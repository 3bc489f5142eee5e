"""The SUMO network built from a site: lanes, lane drop, offsets, speeds, cache."""

from __future__ import annotations

import xml.etree.ElementTree as ET
from pathlib import Path

import numpy as np
import pytest

from wz_shared.site import AreaKind, Site, SpeedLimit
from wz_simulator.traffic.network import (
    NetworkBuildError,
    build_network,
    find_netconvert,
    plan_edges,
    site_hash,
)


def parse_lanes(net_file: Path) -> dict[str, list[ET.Element]]:
    """Normal edges' lanes by edge id, in SUMO lane order."""
    lanes: dict[str, list[ET.Element]] = {}
    for edge in ET.parse(net_file).getroot().iter("edge"):
        if edge.get("function") is None:
            lanes[edge.attrib["id"]] = sorted(
                edge.findall("lane"), key=lambda lane: int(lane.attrib["index"])
            )
    return lanes


def shape_points(lane: ET.Element) -> np.ndarray:
    return np.array(
        [[float(v) for v in point.split(",")] for point in lane.attrib["shape"].split()]
    )


def test_netconvert_is_found() -> None:
    assert find_netconvert().is_file()


def test_network_lanes_follow_the_work_zone(site: Site, sim_work_dir: Path) -> None:
    network = build_network(site, sim_work_dir)
    lanes = parse_lanes(network.net_file)
    taper_end = site.area(AreaKind.TRANSITION).end_station_m
    termination_end = site.area(AreaKind.TERMINATION).end_station_m
    assert network.closed_lane_end_station_m == taper_end
    assert network.reopen_station_m == termination_end
    assert list(lanes) == list(network.route_edge_ids)
    # Edges are cut at every speed-limit and work-zone boundary.
    cuts = {edge.start_station_m for edge in network.edges}
    for area in site.work_zone:
        assert area.start_station_m in cuts
    for limit in site.speed_limits[1:]:
        assert limit.start_station_m in cuts
    for edge in network.edges:
        expected = 1 if taper_end <= edge.start_station_m < termination_end else 2
        assert len(lanes[edge.edge_id]) == expected, edge
        assert len(edge.site_lanes) == expected
        middle = (edge.start_station_m + edge.end_station_m) / 2
        for lane in lanes[edge.edge_id]:
            assert float(lane.attrib["speed"]) == pytest.approx(
                site.speed_limit_mps_at(middle), abs=1e-3
            )
            assert float(lane.attrib["width"]) == pytest.approx(3.66)
    assert network.edges[0].start_station_m == 0.0
    assert network.edges[-1].end_station_m == pytest.approx(site.road_length_m)


def test_lane_centres_sit_at_site_offsets(site: Site, sim_work_dir: Path) -> None:
    network = build_network(site, sim_work_dir)
    lanes = parse_lanes(network.net_file)
    for edge in network.edges:
        for sumo_lane, site_lane in zip(lanes[edge.edge_id], edge.site_lanes, strict=True):
            points = shape_points(sumo_lane)
            station, offset = site.road_frame.to_road(points[:, 0], points[:, 1])
            np.testing.assert_allclose(offset, site.lane(site_lane).center_offset_m, atol=0.02)
            # Lanes run the whole edge: no junction cut-backs.
            assert station[0] == pytest.approx(edge.start_station_m, abs=0.05)
            assert station[-1] == pytest.approx(edge.end_station_m, abs=0.05)


def test_closed_lane_ends_at_the_taper_end(site: Site, sim_work_dir: Path) -> None:
    network = build_network(site, sim_work_dir)
    lanes = parse_lanes(network.net_file)
    taper_end = site.area(AreaKind.TRANSITION).end_station_m
    closed = site.closed_lane_index
    last_with_closed = [
        e for e in network.edges if closed in e.site_lanes and e.end_station_m <= taper_end
    ][-1]
    assert last_with_closed.end_station_m == taper_end
    lane = lanes[last_with_closed.edge_id][last_with_closed.site_lanes.index(closed)]
    end = shape_points(lane)[-1]
    station, offset = site.road_frame.to_road(end[0], end[1])
    assert float(station) == pytest.approx(taper_end, abs=0.01)
    assert float(offset) == pytest.approx(site.lane(closed).center_offset_m, abs=0.01)
    # The closed lane has no successor; every other lane continues; no internal lanes.
    root = ET.parse(network.net_file).getroot()
    assert not [e for e in root.iter("edge") if e.get("function") == "internal"]
    outgoing = {(c.attrib["from"], int(c.attrib["fromLane"])) for c in root.iter("connection")}
    for edge in network.edges[:-1]:
        for sumo_index, site_lane in enumerate(edge.site_lanes):
            dead_end = edge is last_with_closed and site_lane == closed
            assert ((edge.edge_id, sumo_index) in outgoing) != dead_end, (edge, site_lane)
    # After the drop, the one SUMO lane is the site's open lane.
    lane_map = network.lane_site_index()
    dropped = [e for e in network.edges if len(e.site_lanes) == 1]
    assert dropped and all(lane_map[f"{e.edge_id}_0"] == 0 for e in dropped)


def test_build_is_cached_by_site_hash(site: Site, tmp_path: Path) -> None:
    first = build_network(site, tmp_path)
    stamp = first.net_file.stat().st_mtime_ns
    # No netconvert needed the second time.
    again = build_network(site, tmp_path, netconvert=tmp_path / "no-such-netconvert")
    assert again.net_file == first.net_file
    assert again.net_file.stat().st_mtime_ns == stamp
    changed = site.model_copy(
        update={
            "speed_limits": [
                *site.speed_limits[:-1],
                SpeedLimit(start_station_m=1800.0, end_station_m=2000.0, speed_limit_mph=65.0),
            ]
        }
    )
    assert site_hash(changed) != site_hash(site)
    with pytest.raises(NetworkBuildError, match="cannot run netconvert"):
        build_network(changed, tmp_path, netconvert=tmp_path / "no-such-netconvert")


def test_closed_lane_reopens_only_with_room_after_the_termination(site: Site) -> None:
    _, _, reopen = plan_edges(site)
    assert reopen == site.area(AreaKind.TERMINATION).end_station_m
    without_termination = site.model_copy(
        update={"work_zone": [a for a in site.work_zone if a.kind != AreaKind.TERMINATION]}
    )
    edges, _, reopen = plan_edges(without_termination)
    assert reopen is None
    assert len(edges[-1].site_lanes) == 1


def test_a_closed_middle_lane_is_refused(site: Site) -> None:
    lanes = [*site.lanes, site.lanes[-1].model_copy(update={"index": 2, "center_offset_m": 5.49})]
    three = site.model_copy(update={"lanes": lanes})
    with pytest.raises(NetworkBuildError, match="neither the rightmost nor the leftmost"):
        plan_edges(three)
