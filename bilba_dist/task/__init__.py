"""Task files: schema, loading, and the built-in tasks (tasks/*.yaml)."""
