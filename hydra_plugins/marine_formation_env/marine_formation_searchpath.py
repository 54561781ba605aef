"""Hydra plugin: BenchMARL's command line finds the ``marine_formation`` tasks.

Hydra imports every module of the ``hydra_plugins`` namespace package when it
starts. This one adds the project's BenchMARL configs to Hydra's search path
(``task=marine_formation/paper_speed``) and, when BenchMARL is installed, puts
the tasks in BenchMARL's registry, so that ``python -m benchmarl.run`` runs them
with nothing else to write. Without BenchMARL (or if it cannot be imported) it
adds nothing, and other Hydra applications are not affected.
"""

from __future__ import annotations

import importlib.util

from hydra.core.config_search_path import ConfigSearchPath
from hydra.plugins.search_path_plugin import SearchPathPlugin


class MarineFormationSearchPathPlugin(SearchPathPlugin):
    """Appends ``marine_formation_env/benchmarl_conf`` to the search path of BenchMARL's runs."""

    def manipulate_search_path(self, search_path: ConfigSearchPath) -> None:
        if importlib.util.find_spec("benchmarl") is None:
            return
        try:
            from marine_formation_env.benchmarl import CONFIG_DIR  # registers the tasks with BenchMARL
        except ImportError:  # BenchMARL without what it needs: leave every other Hydra app alone
            return

        search_path.append(provider="marine-formation-env", path=f"file://{CONFIG_DIR}")
