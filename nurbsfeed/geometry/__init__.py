"""NURBS geometry: validated curves, evaluation (vectorised and single-parameter), arc length."""

from nurbsfeed.geometry.nurbs import NurbsCurve

__all__ = ["NurbsCurve"]
