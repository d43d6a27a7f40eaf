"""Trajectories against ground truth: Umeyama alignment and evaluation (ATE, RPE, KITTI drift)."""
