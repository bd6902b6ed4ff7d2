"""Calibration pose planning: choose the joint sets worth measuring (:func:`.design.plan_poses`)."""

from .design import CRITERIA, Plan, criterion_value, plan_poses

__all__ = ["CRITERIA", "Plan", "criterion_value", "plan_poses"]
