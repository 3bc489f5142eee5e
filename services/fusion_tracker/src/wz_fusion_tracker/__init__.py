"""Fusion tracker: Kalman late fusion of asynchronous sensors (pure core) and its node.

The pure core, no I/O:

* :mod:`wz_fusion_tracker.kalman`: the Kalman filter of the constant-velocity model of
  :mod:`wz_shared.motion` (paper Eq. 7-10, road-aligned process noise) as functions, one
  filter, and a vectorised bank;
* :mod:`wz_fusion_tracker.paper`: the paper's method (per-sensor smoothing, nearest matching,
  sequential camera-then-LiDAR updates, the simple-average baseline) for reruns;
* the product's multi-target tracker: :mod:`wz_fusion_tracker.tracker` (reorder window and
  cycle), :mod:`~wz_fusion_tracker.settings`, :mod:`~wz_fusion_tracker.types`,
  :mod:`~wz_fusion_tracker.association` (gating, global nearest neighbour),
  :mod:`~wz_fusion_tracker.track_table` (bookkeeping), :mod:`~wz_fusion_tracker.identity`
  (re-acquisition, hand-over, merging);
* :mod:`wz_fusion_tracker.smoothing`: RTS smoothing (:func:`wz_shared.motion.rts_smooth`) of
  a stored track history.
"""
