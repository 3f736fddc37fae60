"""Baseline agents (Stable-Baselines3) on penny_env's environments."""
