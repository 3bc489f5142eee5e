"""The paper's point-cloud pipeline, as the reference detection path (pure core, sensor frame).

Saba et al. (2025), section "Using LiDAR", detect vehicles bottom-up, frame by frame, with no
background model. :class:`ReferencePipeline` runs their steps in their order; each is timed under
its name in :attr:`DetectionResult.timings_s` and each can be switched off in
:class:`ReferenceSettings` (a step that is off, or skipped for want of input, has no timing key):

=========== =====================================================================================
step        what it does
=========== =====================================================================================
(validity)  points with a non-finite x, y or z (no-return slots) are dropped first; not timed.
roi         keep points inside a box in the sensor frame and between a minimum and maximum range.
intensity   drop returns whose intensity is below ``min_intensity``. Returns without an intensity
            (NaN) are kept; when *no* point has one (a sensor or file without the channel) the
            step is skipped altogether.
voxel       average the points of each cube of side ``voxel_size_m`` into one point (what
            open3d's ``voxel_down_sample`` does; done in numpy so that every input point keeps
            the index of its voxel, which maps clusters back to the input for the foreground).
ground      RANSAC plane (open3d ``segment_plane``); a plane is accepted as the road only if its
            normal is within ``ground_max_tilt_deg`` of the sensor's z axis and it holds at least
            ``ground_min_inlier_fraction`` of the points; otherwise its inliers are set aside and
            the next plane tried (``ground_max_attempts`` in all). The accepted plane's inliers
            are removed. No plane (too few points, no level plane): nothing is removed.
height      keep points whose height above the ground plane is in
            [``min_height_m``, ``max_height_m``]: drops what is left of the road surface, points
            below it, and overhead structure (signs, trees, the sensor's own mast). Without a
            plane it uses ``z = fallback_ground_z_m`` if set, else it is skipped.
outliers    statistical outlier removal (open3d ``remove_statistical_outlier``): a point whose
            mean distance to its ``outlier_neighbors`` nearest neighbours exceeds the cloud's mean
            of that distance by more than ``outlier_std_ratio`` standard deviations is dropped.
dbscan      DBSCAN (open3d ``cluster_dbscan``); noise points are dropped. Off: every remaining
            point is one cluster.
merge       agglomerative clustering of the DBSCAN clusters' centroids (scipy ``linkage`` with
            ``merge_linkage``, then ``fcluster`` cut at ``merge_distance_m``): groups whose
            centroids are no farther apart than the cut are joined, which puts back together a
            vehicle split by an occlusion shadow or by sparse beams on a far, tall vehicle. After
            it (always, untimed) clusters with fewer than ``min_cluster_points`` or more than
            ``max_cluster_points`` points are dropped.
boxes       an upright oriented box per cluster, its class from its size, its position and the
            position's covariance (below). Off: no detections, the foreground is still given.
=========== =====================================================================================

Detections
----------
- Position: ``center_xyz_m`` is the **centroid of the cluster's points** (the mean of the
  downsampled points that make up the cluster), as in the paper ("this centroid serves as an
  estimated object center position"), *not* the centre of the box. A roadside sensor sees the
  near side and top of a vehicle, so the centroid lies towards the sensor from the true centre:
  this bias is the reference path's, kept on purpose so that the fast path can be compared with it.
- Box: vehicles stand upright, so the box is upright: the minimum-area rectangle around the
  cluster's x, y (rotating calipers over the convex hull), its z extent as height. The length is
  the longer horizontal side, ``heading_rad`` the direction of that side in (-pi/2, pi/2]
  (a box has no front). open3d's ``get_oriented_bounding_box`` is not used: fitted to the few
  faces a roadside sensor sees, its boxes tilt.
- Class: :func:`class_from_size`, thresholds on length, width and height.
- ``num_points``: input returns of the cluster (those whose voxel is in it), so that the sum over
  detections equals ``foreground.sum()``.
- Covariance: the paper gives none. An isotropic one that grows with range (beam spacing grows
  with range, and a far vehicle is seen by fewer, sparser beams)::

      sigma(r) = position_std_m + position_std_growth_m_per_m * r,   P_xy = sigma(r)^2 I_2

  with ``r`` the horizontal range of the centroid from the sensor [m].
- ``score``: 1 (the pipeline has no confidence).

Foreground
----------
A mask over the *input* points: true where a point's voxel belongs to a cluster that was kept
(after the size limits). Voxel granularity: every return that went into a kept voxel counts,
including any that alone would have failed the height filter. Without the voxel step each point
is its own voxel, and the mask is exact.

Randomness: RANSAC draws from open3d's global generator, seeded with ``ground_random_seed`` before
each fit, so that a frame gives the same result every time.
"""

from __future__ import annotations

import importlib.util
import math
import time
from typing import TYPE_CHECKING, Any, Literal

import numpy as np
from pydantic import BaseModel, ConfigDict, Field, model_validator
from scipy.cluster.hierarchy import fcluster, linkage
from scipy.spatial import ConvexHull, QhullError

from wz_lidar_detector.detection import BoxDetection, DetectionResult, PointFrame
from wz_shared.arrays import F64, I64, Bool
from wz_shared.messages import VehicleClass

if TYPE_CHECKING:
    import open3d as o3d


#: Names of the timed steps, in the order they run.
STEP_NAMES = (
    "roi",
    "intensity",
    "voxel",
    "ground",
    "height",
    "outliers",
    "dbscan",
    "merge",
    "boxes",
)

# Class thresholds [m] of :func:`class_from_size`. A roadside sensor sees part of a vehicle, so
# the limits are loose: a far car seen end-on is short, a truck's cab alone is car-sized.
MIN_VEHICLE_LENGTH_M = 1.0  # shorter: a post, a cone, a pedestrian, a fragment
MIN_VEHICLE_HEIGHT_M = 0.4  # lower: kerb, debris, road left over
MAX_VEHICLE_LENGTH_M = 25.0  # longer: a barrier or wall, not a vehicle
HEAVY_MIN_LENGTH_M = 6.5  # a car is at most about 5.5 m long
HEAVY_MIN_HEIGHT_M = 2.6  # a car or van is at most about 2.3 m high
LONG_MIN_HEIGHT_M = 1.0  # lower and heavy-long: a kerb, barrier or road edge
BUS_LENGTH_M = (10.0, 14.5)  # city and coach buses; trucks are shorter or longer
BUS_HEIGHT_M = (2.8, 3.6)  # buses are lower than box trucks and trailers (about 4 m)
MOTORCYCLE_MAX_LENGTH_M = 2.6
MOTORCYCLE_MAX_WIDTH_M = 1.2


def class_from_size(length_m: float, width_m: float, height_m: float) -> VehicleClass:
    """The vehicle class of an upright box, from its dimensions alone.

    Rules, in order (thresholds are the module's ``*_M`` constants):

    1. not a vehicle's size (length < 1 m or > 25 m, height < 0.4 m, any not finite), or long
       and low (length >= 6.5 m and height < 1 m: a kerb, barrier or road edge): UNKNOWN;
    2. heavy (length >= 6.5 m or height >= 2.6 m): BUS when 10 <= length <= 14.5 m and
       2.8 <= height <= 3.6 m, else TRUCK;
    3. length <= 2.6 m and width <= 1.2 m: MOTORCYCLE;
    4. otherwise CAR.

    Parameters
    ----------
    length_m, width_m, height_m
        Box size [m]: length along the heading, width across it, height.

    Returns
    -------
    VehicleClass
        Size alone cannot tell a bus from a truck of the same size: rule 2 is a guess.
    """
    sizes = (length_m, width_m, height_m)
    if not all(math.isfinite(size) for size in sizes):
        return VehicleClass.UNKNOWN
    if not MIN_VEHICLE_LENGTH_M <= length_m <= MAX_VEHICLE_LENGTH_M:
        return VehicleClass.UNKNOWN
    if height_m < MIN_VEHICLE_HEIGHT_M:
        return VehicleClass.UNKNOWN
    if length_m >= HEAVY_MIN_LENGTH_M and height_m < LONG_MIN_HEIGHT_M:
        return VehicleClass.UNKNOWN
    if length_m >= HEAVY_MIN_LENGTH_M or height_m >= HEAVY_MIN_HEIGHT_M:
        bus_length = BUS_LENGTH_M[0] <= length_m <= BUS_LENGTH_M[1]
        bus_height = BUS_HEIGHT_M[0] <= height_m <= BUS_HEIGHT_M[1]
        return VehicleClass.BUS if bus_length and bus_height else VehicleClass.TRUCK
    if length_m <= MOTORCYCLE_MAX_LENGTH_M and width_m <= MOTORCYCLE_MAX_WIDTH_M:
        return VehicleClass.MOTORCYCLE
    return VehicleClass.CAR


class ReferenceSettings(BaseModel):
    """Parameters of the reference pipeline; every length in metres, in the sensor frame.

    Defaults suit a roadside sensor mounted 3 to 8 m above a road, looking along it, with
    vehicles up to about 130 m away (tuned on a real 80-beam freeway frame and the simulated
    64-beam mast). Narrow the ROI to the carriageway of a site: it is the one setting that
    depends on the site.
    """

    model_config = ConfigDict(frozen=True, extra="forbid")

    # --- roi ---
    # Default: a corridor 40 m wide along the sensor's x axis (a sensor that looks along the
    # road), up to 3 m above the sensor and 12 m below it.
    enable_roi: bool = True
    roi_x_min_m: float = -20.0
    roi_x_max_m: float = 150.0
    roi_y_min_m: float = -20.0
    roi_y_max_m: float = 20.0
    roi_z_min_m: float = -12.0
    roi_z_max_m: float = 3.0
    #: Range from the sensor [m]; the minimum drops returns from the mast and housing.
    roi_min_range_m: float = Field(default=0.5, ge=0.0)
    roi_max_range_m: float = Field(default=150.0, gt=0.0)

    # --- intensity ---
    enable_intensity: bool = True
    #: In the sensor's own intensity units (raw counts, or 0..1 reflectivity in the simulator);
    #: 0 keeps every return. Dark paint and glass return little, so a high value loses vehicles.
    min_intensity: float = 0.0

    # --- voxel ---
    enable_voxel: bool = True
    voxel_size_m: float = Field(default=0.2, gt=0.0)

    # --- ground ---
    enable_ground: bool = True
    ground_distance_threshold_m: float = Field(default=0.2, gt=0.0)
    ground_ransac_n: int = Field(default=3, ge=3)
    ground_iterations: int = Field(default=1000, ge=1)
    ground_max_tilt_deg: float = Field(default=15.0, ge=0.0, le=90.0)
    ground_min_inlier_fraction: float = Field(default=0.05, ge=0.0, le=1.0)
    ground_max_attempts: int = Field(default=3, ge=1)
    ground_random_seed: int = 0

    # --- height ---
    enable_height: bool = True
    min_height_m: float = 0.2
    max_height_m: float = 4.5
    #: Ground height in the sensor frame [m] (minus the mounting height) used by the height
    #: filter when there is no fitted plane; None: the filter needs a fitted plane.
    fallback_ground_z_m: float | None = None

    # --- outliers ---
    enable_outliers: bool = True
    outlier_neighbors: int = Field(default=10, ge=1)
    outlier_std_ratio: float = Field(default=3.0, gt=0.0)

    # --- dbscan ---
    enable_dbscan: bool = True
    dbscan_eps_m: float = Field(default=1.0, gt=0.0)
    dbscan_min_points: int = Field(default=5, ge=1)

    # --- merge ---
    enable_merge: bool = True
    #: Below a lane width (3.5 to 3.7 m), so that vehicles side by side stay apart; above the
    #: 2.85 m between the halves of a car seen abeam and split by a 1.1 m occlusion shadow.
    merge_distance_m: float = Field(default=3.0, ge=0.0)
    #: "centroid": the distance of two groups is that of their centroids (the paper's
    #: wording); "single": the closest pair of member clusters' centroids (chains form).
    merge_linkage: Literal["centroid", "single"] = "centroid"
    min_cluster_points: int = Field(default=5, ge=1)
    max_cluster_points: int = Field(default=100_000, ge=1)

    # --- boxes ---
    enable_boxes: bool = True
    position_std_m: float = Field(default=0.2, gt=0.0)
    position_std_growth_m_per_m: float = Field(default=0.01, ge=0.0)

    @model_validator(mode="after")
    def _check_ranges(self) -> ReferenceSettings:
        pairs = {
            "roi_x": (self.roi_x_min_m, self.roi_x_max_m),
            "roi_y": (self.roi_y_min_m, self.roi_y_max_m),
            "roi_z": (self.roi_z_min_m, self.roi_z_max_m),
            "roi range": (self.roi_min_range_m, self.roi_max_range_m),
            "height": (self.min_height_m, self.max_height_m),
            "cluster points": (self.min_cluster_points, self.max_cluster_points),
        }
        for name, (low, high) in pairs.items():
            if low > high:
                raise ValueError(f"{name}: minimum {low} is above maximum {high}")
        return self


class ReferencePipeline:
    """The paper's pipeline on one frame at a time (stateless between frames).

    Parameters
    ----------
    settings
        Step switches and parameters.
    """

    def __init__(self, settings: ReferenceSettings) -> None:
        if importlib.util.find_spec("open3d") is None:
            raise ModuleNotFoundError(
                "the reference path needs open3d, an optional extra of the LiDAR detector: "
                "install wz-lidar-detector[reference] (the reference container image has it), "
                "or run the fast path (WZ_LIDAR_PATH=fast)"
            )
        self.settings = settings

    def detect(self, frame: PointFrame) -> DetectionResult:
        """Detect vehicles in one frame.

        Parameters
        ----------
        frame
            ``points`` ``(N, 4)`` (or ``(N, 3)``: no intensity): x, y, z [m] in the sensor frame
            and intensity. Non-finite x, y or z marks a point with no return.

        Returns
        -------
        DetectionResult
            Boxes in the sensor frame, the foreground mask ``(N,)`` over the input points, and
            each step's wall time [s] under its name (see the module docstring).

        Raises
        ------
        ValueError
            If ``points`` is not a 2-D array of 3 or 4 columns.
        """
        s = self.settings
        points = np.asarray(frame.points)
        if points.ndim != 2 or points.shape[1] not in (3, 4):
            raise ValueError(
                f"LiDAR points must have shape (N, 4) (x, y, z [m], intensity) or (N, 3), "
                f"got {points.shape}"
            )
        timings: dict[str, float] = {}
        foreground = np.zeros(len(points), dtype=np.bool_)

        xyz_all = points[:, :3].astype(np.float64)
        # Index of each surviving point in the input; narrowed by every step before the voxel one.
        source = np.flatnonzero(np.isfinite(xyz_all).all(axis=1))
        xyz = xyz_all[source]
        has_intensity = points.shape[1] == 4
        intensity = (
            points[source, 3].astype(np.float64) if has_intensity else np.full(len(source), np.nan)
        )

        if s.enable_roi:
            start = time.perf_counter()
            keep = _inside_roi(xyz, s)
            source, xyz, intensity = source[keep], xyz[keep], intensity[keep]
            timings["roi"] = time.perf_counter() - start

        if s.enable_intensity and not np.isnan(intensity).all():
            start = time.perf_counter()
            # A return without intensity is kept: there is no evidence against it.
            keep = ~(intensity < s.min_intensity)
            source, xyz = source[keep], xyz[keep]
            timings["intensity"] = time.perf_counter() - start

        # voxel_of[i]: the voxel (row of ``cloud``) of input point source[i].
        if s.enable_voxel and len(xyz) > 0:
            start = time.perf_counter()
            cloud, voxel_of = _voxel_downsample(xyz, s.voxel_size_m)
            timings["voxel"] = time.perf_counter() - start
        else:
            cloud, voxel_of = xyz, np.arange(len(xyz), dtype=np.int64)
        # cloud_id[j]: the voxel of the j-th point still in the cloud.
        cloud_id = np.arange(len(cloud), dtype=np.int64)

        plane: F64 | None = None
        if s.enable_ground:
            start = time.perf_counter()
            plane = _fit_ground_plane(cloud, s)
            if plane is not None:
                keep = np.abs(_height_above(cloud, plane)) > s.ground_distance_threshold_m
                cloud, cloud_id = cloud[keep], cloud_id[keep]
            timings["ground"] = time.perf_counter() - start

        if plane is None and s.fallback_ground_z_m is not None:
            plane = np.array([0.0, 0.0, 1.0, -s.fallback_ground_z_m])
        if s.enable_height and plane is not None:
            start = time.perf_counter()
            height = _height_above(cloud, plane)
            keep = (height >= s.min_height_m) & (height <= s.max_height_m)
            cloud, cloud_id = cloud[keep], cloud_id[keep]
            timings["height"] = time.perf_counter() - start

        if s.enable_outliers:
            start = time.perf_counter()
            keep_index = _statistical_inliers(cloud, s.outlier_neighbors, s.outlier_std_ratio)
            cloud, cloud_id = cloud[keep_index], cloud_id[keep_index]
            timings["outliers"] = time.perf_counter() - start

        if s.enable_dbscan:
            start = time.perf_counter()
            labels = _dbscan(cloud, s.dbscan_eps_m, s.dbscan_min_points)
            clustered = labels >= 0
            cloud, cloud_id, labels = cloud[clustered], cloud_id[clustered], labels[clustered]
            timings["dbscan"] = time.perf_counter() - start
        else:
            labels = np.zeros(len(cloud), dtype=np.int64)

        if s.enable_merge and len(cloud) > 0:
            start = time.perf_counter()
            labels = _merge_clusters(cloud, labels, s.merge_distance_m, s.merge_linkage)
            timings["merge"] = time.perf_counter() - start

        # Cluster size limits, on the points the clusters were made of.
        counts = np.bincount(labels, minlength=1) if len(labels) else np.zeros(0, np.int64)
        size_ok = (counts >= s.min_cluster_points) & (counts <= s.max_cluster_points)
        kept_labels = np.flatnonzero(size_ok)

        # Input points (among ``source``) of each kept cluster, through their voxel.
        voxel_label = np.full(int(voxel_of.max(initial=-1)) + 1, -1, dtype=np.int64)
        voxel_label[cloud_id] = np.where(size_ok[labels], labels, -1) if len(labels) else -1
        input_label = voxel_label[voxel_of]
        foreground[source[input_label >= 0]] = True
        returns_per_label = np.bincount(input_label[input_label >= 0], minlength=len(counts))

        detections: list[BoxDetection] = []
        if s.enable_boxes:
            start = time.perf_counter()
            for label in kept_labels:
                members = cloud[labels == label]
                detections.append(self._box(members, int(returns_per_label[label])))
            timings["boxes"] = time.perf_counter() - start

        return DetectionResult(detections=detections, foreground=foreground, timings_s=timings)

    def _box(self, members: F64, num_returns: int) -> BoxDetection:
        """Box, class and covariance of one cluster ``(n, 3)`` [m]; its position is the centroid."""
        s = self.settings
        centroid = members.mean(axis=0)
        length, width, heading = _min_area_rectangle(members[:, :2])
        height = float(members[:, 2].max() - members[:, 2].min())
        range_m = math.hypot(float(centroid[0]), float(centroid[1]))
        sigma_m = s.position_std_m + s.position_std_growth_m_per_m * range_m
        variance = sigma_m * sigma_m
        return BoxDetection(
            center_xyz_m=(float(centroid[0]), float(centroid[1]), float(centroid[2])),
            size_lwh_m=(length, width, height),
            heading_rad=heading,
            object_class=class_from_size(length, width, height),
            num_points=num_returns,
            covariance_xy_m2=((variance, 0.0), (0.0, variance)),
        )


# --- steps --------------------------------------------------------------------------------------


def _inside_roi(xyz: F64, s: ReferenceSettings) -> Bool:
    """Mask of points ``(n, 3)`` [m] inside the ROI box and range interval."""
    x, y, z = xyz[:, 0], xyz[:, 1], xyz[:, 2]
    range_sq = x * x + y * y + z * z
    inside: Bool = (
        (x >= s.roi_x_min_m)
        & (x <= s.roi_x_max_m)
        & (y >= s.roi_y_min_m)
        & (y <= s.roi_y_max_m)
        & (z >= s.roi_z_min_m)
        & (z <= s.roi_z_max_m)
        & (range_sq >= s.roi_min_range_m**2)
        & (range_sq <= s.roi_max_range_m**2)
    )
    return inside


def _voxel_downsample(xyz: F64, voxel_size_m: float) -> tuple[F64, I64]:
    """Mean point of each occupied voxel, and each point's voxel.

    Parameters
    ----------
    xyz
        ``(n, 3)`` points [m], n >= 1.
    voxel_size_m
        Side of the cubic voxels [m]; the grid starts at the cloud's minimum corner.

    Returns
    -------
    cloud
        ``(m, 3)`` mean of the points in each voxel [m].
    voxel_of
        ``(n,)`` row of ``cloud`` of each point.
    """
    cell = np.floor((xyz - xyz.min(axis=0)) / voxel_size_m).astype(np.int64)
    span = cell.max(axis=0) + 1
    if float(span[0]) * float(span[1]) * float(span[2]) < 2.0**62:
        key = (cell[:, 0] * span[1] + cell[:, 1]) * span[2] + cell[:, 2]
        _, voxel_of = np.unique(key, return_inverse=True)
    else:  # a cloud kilometres wide with centimetre voxels: compare rows instead
        _, voxel_of = np.unique(cell, axis=0, return_inverse=True)
    voxel_of = voxel_of.reshape(-1).astype(np.int64)
    count = np.bincount(voxel_of).astype(np.float64)
    sums = np.column_stack([np.bincount(voxel_of, weights=xyz[:, k]) for k in range(3)])
    cloud: F64 = sums.astype(np.float64) / count[:, None]
    return cloud, voxel_of


def _open3d() -> Any:
    """open3d, imported on first use: importing it takes a second or more (it brings its
    plotting, dash and plotly, along), which the node on the fast path, which only shares this
    module's box fit, should not pay at every start or restart."""
    import open3d

    return open3d


def _to_open3d(xyz: F64) -> o3d.geometry.PointCloud:
    lib = _open3d()
    cloud: o3d.geometry.PointCloud = lib.geometry.PointCloud(
        lib.utility.Vector3dVector(np.ascontiguousarray(xyz))
    )
    return cloud


def _height_above(xyz: F64, plane: F64) -> F64:
    """Signed distance [m] of points ``(n, 3)`` above ``plane`` (a, b, c, d), unit upward normal."""
    height: F64 = xyz @ plane[:3] + plane[3]
    return height


def _fit_ground_plane(cloud: F64, s: ReferenceSettings) -> F64 | None:
    """The road plane ``(a, b, c, d)`` (unit normal, c > 0) by RANSAC, or None.

    A plane is accepted when its normal is within ``ground_max_tilt_deg`` of z and it holds at
    least ``ground_min_inlier_fraction`` of the cloud; a rejected plane's inliers (a wall, a
    truck's side) are set aside and the next one tried.
    """
    min_inliers = max(s.ground_ransac_n, math.ceil(s.ground_min_inlier_fraction * len(cloud)))
    min_normal_z = math.cos(math.radians(s.ground_max_tilt_deg))
    candidates = np.arange(len(cloud))
    for attempt in range(s.ground_max_attempts):
        if len(candidates) < min_inliers:
            return None
        _open3d().utility.random.seed(s.ground_random_seed + attempt)
        model, inliers = _to_open3d(cloud[candidates]).segment_plane(
            s.ground_distance_threshold_m, s.ground_ransac_n, s.ground_iterations
        )
        plane = np.asarray(model, dtype=np.float64).reshape(4)
        norm = float(np.linalg.norm(plane[:3]))
        if len(inliers) < min_inliers or not math.isfinite(norm) or norm == 0.0:
            return None
        plane /= norm if plane[2] >= 0.0 else -norm
        if plane[2] >= min_normal_z:
            return plane
        candidates = np.delete(candidates, np.asarray(inliers, dtype=np.int64))
    return None


def _statistical_inliers(cloud: F64, neighbors: int, std_ratio: float) -> I64:
    """Rows of ``cloud`` kept by statistical outlier removal.

    With ``neighbors`` or fewer points there are no statistics to judge by, and all are kept.
    """
    if len(cloud) <= neighbors:
        return np.arange(len(cloud), dtype=np.int64)
    _, kept = _to_open3d(cloud).remove_statistical_outlier(neighbors, std_ratio)
    return np.asarray(kept, dtype=np.int64)


def _dbscan(cloud: F64, eps_m: float, min_points: int) -> I64:
    """DBSCAN label of each point (-1: noise)."""
    if len(cloud) == 0:
        return np.zeros(0, dtype=np.int64)
    labels = _to_open3d(cloud).cluster_dbscan(eps_m, min_points, print_progress=False)
    return np.asarray(labels, dtype=np.int64)


def _merge_clusters(cloud: F64, labels: I64, merge_distance_m: float, method: str) -> I64:
    """Agglomerative merge of clusters by their centroids; new labels ``0..k-1`` per point.

    Each cluster enters as one observation, its centroid [m]; scipy's hierarchical clustering
    joins the two closest groups (``method``: centroid or single linkage) until the closest two are
    more than ``merge_distance_m`` apart.
    """
    count = np.bincount(labels).astype(np.float64)
    present = np.flatnonzero(count)
    if len(present) < 2:
        _, compact = np.unique(labels, return_inverse=True)
        return compact.reshape(-1).astype(np.int64)
    centroids = (
        np.column_stack([np.bincount(labels, weights=cloud[:, k]) for k in range(3)])[present]
        / count[present, None]
    )
    tree = linkage(centroids, method=method)
    group = np.asarray(fcluster(tree, t=merge_distance_m, criterion="distance"), np.int64) - 1
    group_of_label = np.full(len(count), -1, dtype=np.int64)
    group_of_label[present] = group
    merged: I64 = group_of_label[labels]
    return merged


def _min_area_rectangle(xy: F64) -> tuple[float, float, float]:
    """Minimum-area rectangle around points ``(n, 2)`` [m].

    Returns
    -------
    tuple
        Length (longer side) [m], width [m], heading of the length side in (-pi/2, pi/2] [rad].
    """
    ring = xy
    if len(xy) >= 3:
        try:
            ring = xy[ConvexHull(xy).vertices]
        except QhullError:  # collinear or coincident points: every edge lies along one line
            ring = xy
    edges = np.roll(ring, -1, axis=0) - ring
    # The best rectangle has a side along a hull edge; a quarter turn gives the same rectangle.
    angles = np.unique(np.mod(np.arctan2(edges[:, 1], edges[:, 0]), 0.5 * math.pi))
    cos_a, sin_a = np.cos(angles)[:, None], np.sin(angles)[:, None]
    along = ring[:, 0] * cos_a + ring[:, 1] * sin_a
    across = -ring[:, 0] * sin_a + ring[:, 1] * cos_a
    extent_along = along.max(axis=1) - along.min(axis=1)
    extent_across = across.max(axis=1) - across.min(axis=1)
    best = int(np.argmin(extent_along * extent_across))
    angle = float(angles[best])
    length, width = float(extent_along[best]), float(extent_across[best])
    if width > length:
        length, width, angle = width, length, angle + 0.5 * math.pi
    heading = angle - math.pi if angle > 0.5 * math.pi else angle
    return length, width, heading
