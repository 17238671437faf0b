"""The `bilba` command."""
