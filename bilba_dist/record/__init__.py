"""MCAP logs of planning jobs: writing, schemas, reading, `bilba logs`."""
