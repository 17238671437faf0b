"""Convex pieces with named faces, parts, poses and contact pairs."""
