"""Seeded episodes of a run config, one at a time or over processes and Ray tasks, in episode order
(`episodes`); the check of a model file against the road it drives (`model_fit`); the confidence
intervals of what the episodes measured (`statistics`)."""
