"""The fast detection path: background subtraction, Euclidean clustering, completed boxes.

A roadside sensor does not move, so what is not background is traffic. :class:`FastPipeline`
replaces the reference path's ROI, voxel, ground, height and outlier steps with one lookup in a
background model (:mod:`wz_lidar_detector.background`), clusters the few foreground points, and
fits each cluster a box completed from its visible faces (:mod:`wz_lidar_detector.boxfit`),
whose centre is the vehicle's, not the centroid of what was seen. Steps, each timed under its
name in :attr:`DetectionResult.timings_s`:

=========== =====================================================================================
step        what it does
=========== =====================================================================================
foreground  ``background.foreground_mask(frame)``, then returns nearer than ``min_range_m`` (the
            mast, the housing) or farther than ``max_range_m`` are dropped. The result's
            ``foreground`` is this mask: the points that went into clustering.
cluster     Euclidean clustering (:func:`euclidean_clusters`): foreground points are averaged
            per cube of ``cluster_cell_m``; cube means closer than ``cluster_eps_m`` are
            linked (``scipy.spatial.cKDTree.query_pairs``), with vertical distances scaled by
            ``cluster_z_scale`` (a far vehicle's beams are far apart vertically) and, beyond
            ``cluster_eps_m / cluster_eps_range_fraction``, a linking distance of
            ``cluster_eps_range_fraction`` times the range (far vehicles return sparse points);
            the connected components (``scipy.sparse.csgraph.connected_components``) are the
            clusters.
boxes       clusters of at least ``min_cluster_points``, largest first: a cluster with at least
            half of its points within ``absorb_margin_m`` of a box already fitted is a fragment
            of that vehicle (a side seen at a grazing angle breaks into columns far apart) and
            only adds to its points; ground-level speckle (top less than
            ``min_top_above_ground_m`` above the ground) and things that do not stand on the
            road (lowest point more than ``max_base_above_ground_m`` above it: foliage, signs,
            birds; only where the background knows the ground) are dropped; the rest get
            :func:`fit_box` with the background's ground height and the heading prior.
update      ``background.update(frame)`` when ``update_background`` (a range-image model
            follows slow changes; a voxel model ignores it).
=========== =====================================================================================

Why Euclidean clustering and not range-image connectivity: it works on organized and unorganized
frames alike; it does not depend on the driver's slot order (the real 80-beam freeway frame in
``samples/real-freeway-lidar`` stores its 80 beams per column one after the other although its header says 80
rows of 1800); and it bridges the no-return holes that dark paint and glass leave in a vehicle,
which cut range-image neighbourhoods. Averaging per cube first bounds its cost by the occupied
cubes, not the points: a truck beside the mast returns thousands of points (plain
``query_pairs`` at 1 m over the 13k foreground points of the real frame finds 8.5 million pairs
and takes 340 ms; over cube means, 3 ms). A cube mean stands for its points, so two points link
when their cube means are within ``cluster_eps_m``: always when the points are closer than
``cluster_eps_m - sqrt(3) * cluster_cell_m``, never when farther than
``cluster_eps_m + sqrt(3) * cluster_cell_m``.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass

import numpy as np
from pydantic import BaseModel, ConfigDict, Field
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components
from scipy.spatial import cKDTree

from wz_lidar_detector.background import BackgroundModel, pack_keys, voxel_indices
from wz_lidar_detector.boxfit import BoxFit, BoxFitSettings, fit_box, hidden_near_end
from wz_lidar_detector.detection import BoxDetection, DetectionResult, PointFrame
from wz_shared.arrays import F64, I64, Bool

#: Names of the timed steps, in the order they run.
STEP_NAMES = ("foreground", "cluster", "boxes", "update")

#: Points of a cluster looked up for its ground height (an even subsample).
_GROUND_SAMPLES = 64


class FastSettings(BaseModel):
    """Parameters of the fast path; lengths in metres, in the sensor frame."""

    model_config = ConfigDict(frozen=True, extra="forbid")

    # --- foreground ---
    #: Returns nearer than this are the mast or housing [m].
    min_range_m: float = Field(default=0.5, ge=0.0)
    #: Returns farther than this are not used [m]; keep it inside the background's extent.
    max_range_m: float = Field(default=150.0, gt=0.0)

    # --- cluster ---
    #: Edge of the cubes the foreground is averaged over before linking [m].
    cluster_cell_m: float = Field(default=0.25, gt=0.0)
    #: Cube means closer than this are one cluster [m]: wider than the gap between a vehicle's
    #: columns, narrower than the gap between vehicles in neighbouring lanes.
    cluster_eps_m: float = Field(default=1.0, gt=0.0)
    #: Vertical distances count this much in the linking: a far vehicle's beams are farther
    #: apart vertically than its columns horizontally (64 beams over 41 deg: 1.1 m at 100 m),
    #: and vehicles do not stand on one another.
    cluster_z_scale: float = Field(default=0.5, gt=0.0, le=1.0)
    #: Beyond ``cluster_eps_m / cluster_eps_range_fraction`` the linking distance is this
    #: fraction of the range (1.5 m at 100 m): far vehicles return sparse points.
    cluster_eps_range_fraction: float = Field(default=0.015, ge=0.0)

    # --- boxes ---
    #: A car end-on at 100 m is about 6 columns wide on a 2048-column sensor.
    min_cluster_points: int = Field(default=5, ge=1)
    #: A cluster whose top is lower than this above the ground is speckle, not a vehicle [m].
    min_top_above_ground_m: float = Field(default=0.4, ge=0.0)
    #: A cluster whose lowest point is higher than this above the ground does not stand on the
    #: road [m] (applied only where the background model knows the ground).
    max_base_above_ground_m: float = Field(default=1.5, gt=0.0)
    #: A smaller cluster with at least half of its points within this of a fitted box's
    #: footprint is a fragment of that vehicle (a side seen at a grazing angle breaks into
    #: columns far apart), counted in its points, not reported [m].
    absorb_margin_m: float = Field(default=0.5, ge=0.0)
    #: Direction of travel in the sensor frame [rad] (the road's direction), or None.
    heading_prior_rad: float | None = None
    #: How far a vehicle's heading may be from the prior [deg].
    heading_tolerance_deg: float = Field(default=10.0, gt=0.0, le=45.0)
    #: Points at which a detection's score reaches 1 (score = min(1, points / this)).
    full_score_points: int = Field(default=50, ge=1)
    box: BoxFitSettings = Field(default_factory=BoxFitSettings)
    #: A cluster reaching down to the lowest beam is cut by the field of view's lower edge (a
    #: vehicle coming out of, or going into, the blind cone under a high mast): its extent
    #: towards the sensor is unknown, and its box, anchored on that edge, stands still while
    #: the vehicle drives out. Its centre gets this std along the vehicle [m] (about half a
    #: truck's 16.5 m over two), more than a new track accepts (the tracker's
    #: ``spawn_max_std_m``): it may update a vehicle's track, not start one. 0: not checked.
    fov_cut_std_m: float = Field(default=5.0, ge=0.0)
    #: Such a cut box is completed from its far end instead, the face the sensor sees whole,
    #: towards the sensor (``fit_box(near_end_cut=True)``): its centre then moves with the
    #: vehicle, and only the length's own spread is in its covariance, not
    #: ``fov_cut_std_m``. False: completed from the cut edge, with ``fov_cut_std_m``.
    fov_cut_from_far_end: bool = True

    # --- update ---
    update_background: bool = True


def euclidean_clusters(
    xyz_m: F64,
    cell_m: float,
    eps_m: float,
    z_scale: float = 1.0,
    eps_range_fraction: float = 0.0,
) -> I64:
    """Label points by Euclidean connectivity over cube means (see the module docstring).

    Parameters
    ----------
    xyz_m
        ``(M, 3)`` finite points [m], sensor at the origin.
    cell_m
        Cube edge [m].
    eps_m
        Linking distance between cube means [m].
    z_scale
        Factor on z before linking (distances are taken over ``(x, y, z_scale * z)``).
    eps_range_fraction
        Far away the linking distance grows with range: two cube means link when closer than
        ``max(eps_m, eps_range_fraction * r)``, ``r`` the horizontal range of the nearer one.

    Returns
    -------
    I64
        ``(M,)`` cluster label of each point, 0 .. (clusters - 1).
    """
    if len(xyz_m) == 0:
        return np.zeros(0, dtype=np.int64)
    if z_scale != 1.0:
        xyz_m = xyz_m * np.array([1.0, 1.0, z_scale])
    keys = pack_keys(voxel_indices(xyz_m, cell_m))
    _, cube_of_point, points_per_cube = np.unique(keys, return_inverse=True, return_counts=True)
    cube_of_point = cube_of_point.reshape(-1)
    cubes = len(points_per_cube)
    means = (
        np.column_stack(
            [
                np.bincount(cube_of_point, weights=xyz_m[:, axis], minlength=cubes)
                for axis in range(3)
            ]
        )
        / points_per_cube[:, None]
    )
    pairs = cKDTree(means).query_pairs(eps_m, output_type="ndarray")
    if eps_range_fraction > 0.0:
        # A second, wider search among the few far cube means only: a wide search over all of
        # them would find hundreds of pairs per cube on a near truck.
        ranges = np.hypot(means[:, 0], means[:, 1])
        far = np.flatnonzero(ranges > eps_m / eps_range_fraction)
        if len(far) > 1:
            reach = eps_range_fraction * float(ranges[far].max())
            far_pairs = cKDTree(means[far]).query_pairs(reach, output_type="ndarray")
            first, second = far[far_pairs[:, 0]], far[far_pairs[:, 1]]
            distance = np.linalg.norm(means[first] - means[second], axis=1)
            near_enough = distance <= eps_range_fraction * np.minimum(ranges[first], ranges[second])
            extra = np.column_stack([first[near_enough], second[near_enough]])
            pairs = np.concatenate([pairs.reshape(-1, 2), extra])
    graph = coo_matrix(
        (np.ones(len(pairs), dtype=np.int8), (pairs[:, 0], pairs[:, 1])), shape=(cubes, cubes)
    )
    _, cube_labels = connected_components(graph, directed=False)
    labels: I64 = np.asarray(cube_labels, dtype=np.int64)[cube_of_point]
    return labels


@dataclass
class _Fitted:
    """A fitted box and the points it has taken in (its own and absorbed fragments)."""

    fit: BoxFit
    num_points: int
    #: Cut by the lower edge of the field of view (see ``FastSettings.fov_cut_std_m``).
    fov_cut: bool = False

    def contains_xy(self, xy_m: F64, margin_m: float) -> Bool:
        """Which ``(K, 2)`` points [m] fall in the box's footprint grown by ``margin_m``."""
        centre = np.asarray(self.fit.center_xyz_m[:2])
        heading = self.fit.heading_rad
        axes = np.array(
            [[math.cos(heading), -math.sin(heading)], [math.sin(heading), math.cos(heading)]]
        )
        local = (xy_m - centre) @ axes
        half = 0.5 * np.asarray(self.fit.size_lwh_m[:2]) + margin_m
        inside: Bool = (np.abs(local[:, 0]) <= half[0]) & (np.abs(local[:, 1]) <= half[1])
        return inside


def _lowest_beam_rad(frame: PointFrame) -> tuple[float, float] | None:
    """The lowest beam's elevation and half the beam spacing [rad], from an organized frame's
    returns (each beam's median elevation in the sensor frame); None for an unorganized one
    or a frame with too few returns to tell."""
    if not frame.organized:
        return None
    xyz = frame.points[:, :3].astype(np.float64).reshape(frame.rows, frame.columns, 3)
    with np.errstate(invalid="ignore"):
        elevation = np.arctan2(xyz[..., 2], np.hypot(xyz[..., 0], xyz[..., 1]))
    counts = np.isfinite(elevation).sum(axis=1)
    if (counts >= 8).sum() < 2:
        return None
    with np.errstate(all="ignore"):
        beams = np.sort(np.nanmedian(elevation[counts >= 8], axis=1))
    spacing = float(np.median(np.diff(beams))) if len(beams) > 1 else 0.0
    return float(beams[0]), 0.5 * spacing


def _reaches_floor(cluster: F64, floor: tuple[float, float]) -> bool:
    """Whether a cluster has a return on the lowest beam (within half a beam spacing)."""
    lowest, half = floor
    elevation = np.arctan2(cluster[:, 2], np.hypot(cluster[:, 0], cluster[:, 1]))
    return bool(elevation.min() <= lowest + half)


class FastPipeline:
    """Background subtraction, clustering and completed boxes for one sensor.

    Parameters
    ----------
    settings
        Parameters of the path.
    background
        The sensor's background model; :meth:`detect` updates it when
        ``settings.update_background``.
    """

    def __init__(self, settings: FastSettings, background: BackgroundModel) -> None:
        self.settings = settings
        self.background = background
        #: The lowest beam (:func:`_lowest_beam_rad`), from the first frame that tells it:
        #: a sensor's beams do not move.
        self._floor: tuple[float, float] | None = None

    def detect(self, frame: PointFrame) -> DetectionResult:
        """Detect vehicles in one frame.

        Parameters
        ----------
        frame
            Points in the sensor frame; organized or not, as the background model needs.

        Returns
        -------
        DetectionResult
            Boxes in the sensor frame, the foreground mask ``(N,)`` and the time of each step.

        Raises
        ------
        ShapeMismatchError
            From a range-image background when the frame's layout differs from the model's.
        """
        settings = self.settings
        timings: dict[str, float] = {}

        start = time.perf_counter()
        mask = self.background.foreground_mask(frame)
        index = np.flatnonzero(mask)
        xyz = frame.points[index, :3].astype(np.float64)
        ranges = np.sqrt(xyz[:, 0] ** 2 + xyz[:, 1] ** 2 + xyz[:, 2] ** 2)
        in_range = (ranges >= settings.min_range_m) & (ranges <= settings.max_range_m)
        index, xyz = index[in_range], xyz[in_range]
        foreground = np.zeros(len(frame.points), dtype=bool)
        foreground[index] = True
        timings["foreground"] = time.perf_counter() - start

        start = time.perf_counter()
        labels = euclidean_clusters(
            xyz,
            settings.cluster_cell_m,
            settings.cluster_eps_m,
            settings.cluster_z_scale,
            settings.cluster_eps_range_fraction,
        )
        timings["cluster"] = time.perf_counter() - start

        start = time.perf_counter()
        if self._floor is None and settings.fov_cut_std_m > 0.0:
            self._floor = _lowest_beam_rad(frame)
        floor = self._floor if settings.fov_cut_std_m > 0.0 else None
        detections = self._boxes(xyz, labels, floor)
        timings["boxes"] = time.perf_counter() - start

        if settings.update_background:
            start = time.perf_counter()
            self.background.update(frame)
            timings["update"] = time.perf_counter() - start

        return DetectionResult(detections=detections, foreground=foreground, timings_s=timings)

    def _boxes(
        self, xyz: F64, labels: I64, floor: tuple[float, float] | None = None
    ) -> list[BoxDetection]:
        """``floor``: the lowest beam's elevation and half a beam spacing [rad], or None."""
        settings = self.settings
        if len(labels) == 0:
            return []
        sizes = np.bincount(labels)
        order = np.argsort(labels, kind="stable")
        starts = np.concatenate([[0], np.cumsum(sizes)])
        tolerance_rad = math.radians(settings.heading_tolerance_deg)
        fitted: list[_Fitted] = []
        # Largest first, so that a fragment meets the box of the vehicle it belongs to.
        by_size = np.argsort(-sizes, kind="stable")
        candidates = by_size[sizes[by_size] >= settings.min_cluster_points]
        clusters = [xyz[order[starts[label] : starts[label + 1]]] for label in candidates]
        grounds = self._ground_heights(clusters)
        for label, cluster, ground in zip(candidates.tolist(), clusters, grounds, strict=True):
            owner = self._owner(fitted, cluster[:, :2])
            if owner is not None:
                owner.num_points += len(cluster)
                continue
            top, base = float(cluster[:, 2].max()), float(cluster[:, 2].min())
            if top - (base if ground is None else min(ground, base)) < (
                settings.min_top_above_ground_m
            ):
                continue
            if ground is not None and base - ground > settings.max_base_above_ground_m:
                continue

            def fitted_box(
                near_end_hidden: bool = False,
                near_end_cut: bool = False,
                cluster: F64 = cluster,
                ground: float | None = ground,
            ) -> BoxFit:
                return fit_box(
                    cluster,
                    heading_prior_rad=settings.heading_prior_rad,
                    heading_tolerance_rad=tolerance_rad,
                    ground_z_m=ground,
                    settings=settings.box,
                    near_end_hidden=near_end_hidden,
                    near_end_cut=near_end_cut,
                    beams_rad=None if floor is None else (floor[0], 2.0 * floor[1]),
                )

            cut = floor is not None and _reaches_floor(cluster, floor)
            if cut and settings.fov_cut_from_far_end:
                # The near end is where the field of view cuts the vehicle: the far end is
                # the face (whatever hides the near end, the far end places the box).
                fit = fitted_box(near_end_cut=True)
            else:
                fit = fitted_box()
                # Completed from the end nearer the sensor: is that end a face, or where a
                # nearer vehicle hides the rest (a truck behind a car in the near lane)?
                if fit.completed_lw[0] and hidden_near_end(
                    cluster,
                    fit.heading_rad,
                    xyz[labels != label],
                    angle_tolerance_rad=math.radians(2.0 * settings.box.angular_resolution_deg),
                ):
                    fit = fitted_box(near_end_hidden=True)
            fitted.append(_Fitted(fit, len(cluster), cut))
        return [self._detection(box) for box in fitted]

    def _ground_heights(self, clusters: list[F64]) -> list[float | None]:
        """Median ground height [m] under each cluster (None where unknown), in one lookup."""
        samples = [c[:: max(1, math.ceil(len(c) / _GROUND_SAMPLES)), :2] for c in clusters]
        if not samples:
            return []
        heights = self.background.ground_z_m(np.concatenate(samples))
        grounds: list[float | None] = []
        start = 0
        for sample in samples:
            known = heights[start : start + len(sample)]
            known = known[np.isfinite(known)]
            grounds.append(float(np.median(known)) if len(known) else None)
            start += len(sample)
        return grounds

    def _owner(self, fitted: list[_Fitted], xy_m: F64) -> _Fitted | None:
        """The first fitted box holding at least half of ``(K, 2)`` points, if any."""
        margin_m = self.settings.absorb_margin_m
        centre = xy_m.mean(axis=0)
        spread = float(np.max(np.hypot(*(xy_m - centre).T)))
        for box in fitted:
            # Cheap rejection first: the box's circumscribed circle, grown by the margin.
            reach = 0.5 * math.hypot(*box.fit.size_lwh_m[:2]) + margin_m + spread
            if math.dist(centre, box.fit.center_xyz_m[:2]) > reach:
                continue
            if box.contains_xy(xy_m, margin_m).mean() >= 0.5:
                return box
        return None

    def _detection(self, box: _Fitted) -> BoxDetection:
        fit, covariance = box.fit, box.fit.covariance_xy_m2
        if box.fov_cut and not fit.completed_from_far_end:
            along = np.array([math.cos(fit.heading_rad), math.sin(fit.heading_rad)])
            covariance = covariance + self.settings.fov_cut_std_m**2 * np.outer(along, along)
        return BoxDetection(
            center_xyz_m=fit.center_xyz_m,
            size_lwh_m=fit.size_lwh_m,
            heading_rad=fit.heading_rad,
            object_class=fit.object_class,
            num_points=box.num_points,
            covariance_xy_m2=(
                (float(covariance[0, 0]), float(covariance[0, 1])),
                (float(covariance[1, 0]), float(covariance[1, 1])),
            ),
            score=min(1.0, box.num_points / self.settings.full_score_points),
            completed_from_far_end=fit.completed_from_far_end,
        )
