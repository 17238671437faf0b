"""Plan files: the JSON a planner writes and a Panda controller (or `bilba validate`) reads."""
