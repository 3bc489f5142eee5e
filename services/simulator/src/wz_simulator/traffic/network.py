"""SUMO road network of a site: plain-XML nodes, edges and connections, then netconvert.

The carriageway is cut into edges at every speed-limit and work-zone boundary (SUMO gives one
speed per lane, and a lane count per edge). Each edge follows the site centerline; its shape is
the centerline moved sideways to the middle of the lanes it carries and laid out with
``spreadType="center"``, so every SUMO lane centre sits at its site lane's ``center_offset_m``:

- upstream of the end of the transition (taper) area all site lanes are present;
- from the taper end on, the closed lane (``site.closed_lane_index``) is gone: it has no
  successor, so SUMO's vehicles must leave it before its end (a lane drop, never a teleport);
- the closed lane comes back at the end of the termination area when the site has one that ends
  at least ``MIN_REOPEN_LENGTH_M`` before the end of the road (MUTCD: traffic returns to the
  normal lanes there); otherwise the road continues with the open lanes to its end.

Junctions get a custom zero-depth shape (the line across the road at the node's station), so
edges are not cut back around the nodes and lane ends sit exactly at their stations, and the
network is built without internal lanes: a vehicle goes from the end of one lane straight onto
the start of the next and always reports a real lane of the carriageway.

The build is cached: the output folder is named after a hash of the site description and of
this builder's version, so a second run on the same site does not call netconvert again.
"""

from __future__ import annotations

import hashlib
import itertools
import logging
import math
import os
import shutil
import subprocess
import sys
import tempfile
import xml.etree.ElementTree as ET
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from wz_shared.site import AreaKind, Site

logger = logging.getLogger(__name__)

#: Bump when the network layout or the netconvert options change, to invalidate caches.
BUILDER_VERSION = "2"
#: Boundaries closer than this are merged into one [m] (avoids sliver edges).
MIN_EDGE_LENGTH_M = 1.0
#: The closed lane reopens only if at least this much road is left after the termination [m].
MIN_REOPEN_LENGTH_M = 50.0
#: Edge shapes get a vertex at least this often along the centerline [m] (curves).
MAX_SHAPE_SPACING_M = 25.0

NET_FILE_NAME = "road.net.xml"
_NETCONVERT_OPTIONS = (
    "--offset.disable-normalization",
    "true",  # keep the site frame: SUMO x/y are site x/y
    "--no-internal-links",
    "true",
    "--no-turnarounds",
    "true",
    "--junctions.corner-detail",
    "0",
    "--geometry.remove",
    "false",
    "--lefthand",
    "false",
    "--precision",
    "4",  # mm positions and the speed limits to 1e-4 m/s (default: 2 decimals)
)


class NetworkBuildError(RuntimeError):
    """netconvert failed, or could not be found, or produced an unexpected network."""


@dataclass(frozen=True)
class EdgePlan:
    """One SUMO edge: a stretch of road with a fixed lane set and speed.

    Attributes
    ----------
    edge_id
        SUMO edge id.
    start_station_m, end_station_m
        Stations of its start and end along the site centerline [m].
    site_lanes
        Site lane index of each SUMO lane, in SUMO order (index 0 rightmost).
    speed_limit_mps
        Lane speed [m/s]: the posted limit in the middle of the edge.
    shape_offset_m
        Lateral offset of the edge shape from the centerline [m], left positive: the middle of
        the edge's lanes.
    """

    edge_id: str
    start_station_m: float
    end_station_m: float
    site_lanes: tuple[int, ...]
    speed_limit_mps: float
    shape_offset_m: float

    @property
    def lane_ids(self) -> tuple[str, ...]:
        """SUMO lane ids, in SUMO lane order."""
        return tuple(f"{self.edge_id}_{i}" for i in range(len(self.site_lanes)))


@dataclass(frozen=True)
class RoadNetwork:
    """A built SUMO network and how it maps onto the site.

    Attributes
    ----------
    net_file
        The ``.net.xml`` file.
    edges
        The edges in driving order (the one route every vehicle takes).
    closed_lane_end_station_m
        Station where the closed lane ends: the end of the transition area [m].
    reopen_station_m
        Station where the closed lane starts again [m], or None if it does not.
    site_hash
        Hash of the site description and builder version (names the cache folder).
    """

    net_file: Path
    edges: tuple[EdgePlan, ...]
    closed_lane_index: int
    closed_lane_end_station_m: float
    reopen_station_m: float | None
    site_hash: str

    @property
    def route_edge_ids(self) -> tuple[str, ...]:
        return tuple(edge.edge_id for edge in self.edges)

    def lane_site_index(self) -> dict[str, int]:
        """Map every SUMO lane id to its site lane index."""
        return {
            lane_id: site_lane
            for edge in self.edges
            for lane_id, site_lane in zip(edge.lane_ids, edge.site_lanes, strict=True)
        }


def site_hash(site: Site) -> str:
    """Hex digest naming a network build: the site description plus the builder version."""
    digest = hashlib.sha256()
    digest.update(BUILDER_VERSION.encode())
    digest.update(site.model_dump_json().encode())
    return digest.hexdigest()[:16]


def find_netconvert() -> Path:
    """Locate the netconvert binary shipped with eclipse-sumo.

    Looks on ``PATH``, next to the running interpreter (a virtual environment's ``bin``), then
    in ``$SUMO_HOME/bin`` and the ``sumo`` package's ``bin`` folder.
    """
    candidates: list[Path] = []
    found = shutil.which("netconvert")
    if found:
        candidates.append(Path(found))
    candidates.append(Path(sys.executable).parent / "netconvert")
    sumo_home = os.environ.get("SUMO_HOME")
    if sumo_home:
        candidates.append(Path(sumo_home) / "bin" / "netconvert")
    try:
        import sumo  # the eclipse-sumo wheel

        candidates.append(Path(sumo.SUMO_HOME) / "bin" / "netconvert")
    except ImportError:
        pass
    for candidate in candidates:
        if candidate.is_file() and os.access(candidate, os.X_OK):
            return candidate
    raise NetworkBuildError(
        "netconvert not found (looked on PATH, next to the Python interpreter, in "
        "$SUMO_HOME/bin and in the eclipse-sumo package): install eclipse-sumo"
    )


def _lane_order(site: Site) -> list[int]:
    return sorted(lane.index for lane in site.lanes)


def _check_lanes_adjacent(site: Site) -> None:
    """SUMO lanes touch each other: the site's lanes must too (no gaps, no overlaps)."""
    lanes = sorted(site.lanes, key=lambda lane: lane.index)
    for right, left in itertools.pairwise(lanes):
        expected = right.center_offset_m + (right.width_m + left.width_m) / 2.0
        if abs(left.center_offset_m - expected) > 0.01:
            raise NetworkBuildError(
                f"site {site.site_id}: lanes {right.index} and {left.index} do not touch "
                f"(offsets {right.center_offset_m} and {left.center_offset_m} m with widths "
                f"{right.width_m} and {left.width_m} m); SUMO cannot model a gap between lanes"
            )


def _shape_offset_m(site: Site, lanes: Sequence[int]) -> float:
    """Offset of the middle of a contiguous lane set from the centerline [m]."""
    right = site.lane(min(lanes))
    left = site.lane(max(lanes))
    return (right.center_offset_m - right.width_m / 2 + left.center_offset_m + left.width_m / 2) / 2


def plan_edges(site: Site) -> tuple[list[EdgePlan], float, float | None]:
    """Cut the road into edges at speed-limit and work-zone boundaries.

    Returns
    -------
    edges
        The edges in driving order.
    closed_lane_end_station_m
        End of the transition area [m], where the closed lane ends.
    reopen_station_m
        Where the closed lane comes back [m], or None.
    """
    _check_lanes_adjacent(site)
    order = _lane_order(site)
    closed = site.closed_lane_index
    if closed not in (order[0], order[-1]):
        raise NetworkBuildError(
            f"site {site.site_id}: closed lane {closed} is neither the rightmost nor the "
            "leftmost lane; only a lane drop at an edge of the carriageway is supported"
        )
    road_length_m = site.road_length_m
    taper_end_m = site.area(AreaKind.TRANSITION).end_station_m
    reopen_m: float | None = None
    try:
        termination_end_m = site.area(AreaKind.TERMINATION).end_station_m
        if termination_end_m <= road_length_m - MIN_REOPEN_LENGTH_M:
            reopen_m = termination_end_m
    except KeyError:
        pass

    cuts = {0.0, road_length_m, taper_end_m}
    for limit in site.speed_limits:
        cuts.update((limit.start_station_m, limit.end_station_m))
    for area in site.work_zone:
        cuts.update((area.start_station_m, area.end_station_m))
    if reopen_m is not None:
        cuts.add(reopen_m)
    stations = [0.0]
    for station in sorted(s for s in cuts if 0.0 < s <= road_length_m):
        if station - stations[-1] >= MIN_EDGE_LENGTH_M:
            stations.append(station)
    # Snap the last cut to the road end (a boundary just short of it would leave a sliver).
    stations[-1] = road_length_m
    if len(stations) < 2:
        raise NetworkBuildError(f"site {site.site_id}: road too short for a network")

    open_lanes = [index for index in order if index != closed]
    edges: list[EdgePlan] = []
    for i, (start_m, end_m) in enumerate(itertools.pairwise(stations)):
        middle_m = (start_m + end_m) / 2
        dropped = middle_m > taper_end_m and (reopen_m is None or middle_m < reopen_m)
        lanes = tuple(open_lanes if dropped else order)
        edges.append(
            EdgePlan(
                edge_id=f"e{i:02d}",
                start_station_m=start_m,
                end_station_m=end_m,
                site_lanes=lanes,
                speed_limit_mps=site.speed_limit_mps_at(middle_m),
                shape_offset_m=_shape_offset_m(site, lanes),
            )
        )
    return edges, taper_end_m, reopen_m


def _shape_stations(vertex_stations: np.ndarray, start_m: float, end_m: float) -> np.ndarray:
    """Stations for an edge shape: its ends, the centerline vertices between, densified."""
    inner = vertex_stations[(vertex_stations > start_m + 0.01) & (vertex_stations < end_m - 0.01)]
    knots = np.concatenate(([start_m], inner, [end_m]))
    stations: list[float] = []
    for a, b in itertools.pairwise(knots):
        pieces = max(1, math.ceil((b - a) / MAX_SHAPE_SPACING_M))
        stations.extend(np.linspace(a, b, pieces, endpoint=False).tolist())
    stations.append(float(end_m))
    return np.asarray(stations)


def _fmt_shape(xs: np.ndarray, ys: np.ndarray) -> str:
    return " ".join(f"{x:.3f},{y:.3f}" for x, y in zip(xs, ys, strict=True))


def write_plain_xml(site: Site, edges: Sequence[EdgePlan], folder: Path) -> tuple[Path, Path, Path]:
    """Write the plain-XML node, edge and connection files of a planned network.

    Returns
    -------
    The node, edge and connection file paths.
    """
    frame = site.road_frame
    vertex_stations = frame.vertex_stations_m
    lanes_right = min(lane.center_offset_m - lane.width_m / 2 for lane in site.lanes)
    lanes_left = max(lane.center_offset_m + lane.width_m / 2 for lane in site.lanes)

    node_stations = [edges[0].start_station_m] + [edge.end_station_m for edge in edges]
    nodes = ET.Element("nodes")
    for i, station_m in enumerate(node_stations):
        (x,), (y,) = frame.to_site(np.array([station_m]), np.array([0.0]))
        xs, ys = frame.to_site(
            np.array([station_m, station_m]), np.array([lanes_right, lanes_left])
        )
        attrs = {"id": f"n{i:02d}", "x": f"{x:.3f}", "y": f"{y:.3f}", "type": "priority"}
        if 0 < i < len(node_stations) - 1:
            # A zero-depth junction: netconvert does not cut the edges back around the node.
            attrs["shape"] = _fmt_shape(xs, ys)
        ET.SubElement(nodes, "node", attrs)

    edges_xml = ET.Element("edges")
    for i, edge in enumerate(edges):
        stations = _shape_stations(vertex_stations, edge.start_station_m, edge.end_station_m)
        xs, ys = frame.to_site(stations, np.full_like(stations, edge.shape_offset_m))
        element = ET.SubElement(
            edges_xml,
            "edge",
            {
                "id": edge.edge_id,
                "from": f"n{i:02d}",
                "to": f"n{i + 1:02d}",
                "numLanes": str(len(edge.site_lanes)),
                "speed": f"{edge.speed_limit_mps:.4f}",
                "spreadType": "center",
                "shape": _fmt_shape(xs, ys),
            },
        )
        for sumo_index, site_index in enumerate(edge.site_lanes):
            ET.SubElement(
                element,
                "lane",
                {"index": str(sumo_index), "width": f"{site.lane(site_index).width_m:.3f}"},
            )

    connections = ET.Element("connections")
    for upstream, downstream in itertools.pairwise(edges):
        for from_lane, site_index in enumerate(upstream.site_lanes):
            if site_index in downstream.site_lanes:
                ET.SubElement(
                    connections,
                    "connection",
                    {
                        "from": upstream.edge_id,
                        "to": downstream.edge_id,
                        "fromLane": str(from_lane),
                        "toLane": str(downstream.site_lanes.index(site_index)),
                    },
                )

    paths = (folder / "road.nod.xml", folder / "road.edg.xml", folder / "road.con.xml")
    for tree, path in zip((nodes, edges_xml, connections), paths, strict=True):
        ET.indent(tree)
        ET.ElementTree(tree).write(path, encoding="utf-8", xml_declaration=True)
    return paths


def _check_built(net_file: Path, edges: Sequence[EdgePlan]) -> None:
    """Refuse a network whose lane counts differ from the plan."""
    built: dict[str, int] = {}
    for element in ET.parse(net_file).getroot().iter("edge"):
        if element.get("function") in (None, "normal"):
            built[element.get("id", "")] = len(element.findall("lane"))
    for edge in edges:
        if built.get(edge.edge_id) != len(edge.site_lanes):
            raise NetworkBuildError(
                f"{net_file}: edge {edge.edge_id} has {built.get(edge.edge_id)} lanes, "
                f"expected {len(edge.site_lanes)}"
            )


def build_network(site: Site, work_dir: Path, netconvert: Path | None = None) -> RoadNetwork:
    """Build (or reuse) the SUMO network of a site under ``work_dir``.

    Parameters
    ----------
    site
        The site description.
    work_dir
        Folder for builds; the network goes to ``work_dir/net-<hash>/road.net.xml``.
    netconvert
        The netconvert binary; found with :func:`find_netconvert` when None.

    Raises
    ------
    NetworkBuildError
        If netconvert is missing or fails, or the site cannot be modelled.
    """
    edges, taper_end_m, reopen_m = plan_edges(site)
    digest = site_hash(site)
    folder = Path(work_dir) / f"net-{digest}"
    net_file = folder / NET_FILE_NAME
    network = RoadNetwork(
        net_file=net_file,
        edges=tuple(edges),
        closed_lane_index=site.closed_lane_index,
        closed_lane_end_station_m=taper_end_m,
        reopen_station_m=reopen_m,
        site_hash=digest,
    )
    if net_file.is_file():
        logger.debug("reusing SUMO network %s", net_file)
        return network

    Path(work_dir).mkdir(parents=True, exist_ok=True)
    binary = netconvert or find_netconvert()
    # Build in a private folder, then rename: concurrent builders never see half a network.
    with tempfile.TemporaryDirectory(dir=work_dir, prefix=f".net-{digest}-") as scratch:
        scratch_dir = Path(scratch)
        nod, edg, con = write_plain_xml(site, edges, scratch_dir)
        command = [
            str(binary),
            "--node-files",
            str(nod),
            "--edge-files",
            str(edg),
            "--connection-files",
            str(con),
            "--output-file",
            str(scratch_dir / NET_FILE_NAME),
            *_NETCONVERT_OPTIONS,
        ]
        try:
            result = subprocess.run(command, capture_output=True, text=True, check=False)
        except OSError as exc:
            raise NetworkBuildError(f"cannot run netconvert {binary}: {exc}") from exc
        if result.returncode != 0:
            raise NetworkBuildError(
                f"netconvert failed for site {site.site_id} (exit {result.returncode}):\n"
                f"{result.stderr.strip() or result.stdout.strip()}"
            )
        _check_built(scratch_dir / NET_FILE_NAME, edges)
        try:
            os.replace(scratch_dir, folder)
        except OSError:
            if not net_file.is_file():  # not a concurrent builder winning the race
                raise
        else:
            # The scratch folder moved; recreate it so TemporaryDirectory's cleanup is happy.
            scratch_dir.mkdir()
    logger.info(
        "built SUMO network for site %s: %d edges, closed lane %d ends at %.1f m -> %s",
        site.site_id,
        len(edges),
        site.closed_lane_index,
        taper_end_m,
        net_file,
    )
    return network
