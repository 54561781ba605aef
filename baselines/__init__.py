"""Reference policies and evaluation for marine_formation_env.

``ReferencePolicy`` is the paper's controller (LOS path following plus the
atan-saturated consensus law) acting on the masked per-agent observations.
"""

from baselines.reference import ReferencePolicy

__all__ = ["ReferencePolicy"]
