"""Particles and beliefs."""
