"""Tracking sessions: a sliding-window factor graph over a walk's camera poses, fused with the
client's own odometry (ARKit / ARCore / any VIO). See :mod:`quadloc.service.tracking.session`."""
