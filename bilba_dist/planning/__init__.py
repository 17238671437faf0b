"""The planners: BILBA (bilevel) and B-EST (the baseline), their searches and results."""
