"""C-obstacle slices: Minkowski polytopes, boundary vertices, point queries, sampling."""
