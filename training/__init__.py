"""Training for marine_formation_env: three trainers of one shared policy, and their run folders.

``python -m training.train`` (Stable-Baselines3), ``python -m training.torchrl_ppo`` (TorchRL MAPPO/IPPO) and
``python -m training.rllib_ppo`` (RLlib PPO) read one config vocabulary (``training/configs/``) and write one
run-folder contract (``training.run_folder``).
"""
