"""Exploration data segmented by sub-goal, stored as LeRobot v3.0 datasets."""
