"""bilba_dist: bi-level belief assembly planning, distributed on Ray."""

__version__ = "0.1.0"
