"""Training scripts for marine_formation_env (Stable-Baselines3, parameter sharing).

The training pipeline (``python -m training.train``) is tracked in issue 3; this
package holds its configs and entry points.
"""
