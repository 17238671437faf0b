"""The contact-mode graph: modes, belief-dependent edge costs, Dijkstra, pruning."""
