"""Training stages: the oracle (PPO with privileged inputs)."""
