"""Policies for ARS: the shared flat-parameter policies (``LinearPolicy`` as in the ARS paper)."""

from sb3_es.common.policies import FlatPolicy, LinearPolicy, MlpPolicy

__all__ = ["FlatPolicy", "LinearPolicy", "MlpPolicy"]
