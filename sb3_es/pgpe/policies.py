"""Policies for PGPE: the shared flat-parameter policies."""

from sb3_es.common.policies import FlatPolicy, LinearPolicy, MlpPolicy

__all__ = ["FlatPolicy", "LinearPolicy", "MlpPolicy"]
