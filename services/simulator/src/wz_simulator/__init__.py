"""Simulator service: SUMO work-zone traffic with ground truth."""
