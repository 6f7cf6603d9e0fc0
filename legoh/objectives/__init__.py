"""Losses and their set-up: PPO (torchrl), the adaptation module's regression."""
