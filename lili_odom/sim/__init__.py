"""Synthetic data: degenerate shape pairs and a simulated Husky (OS1-128, IMU, wheels) in worlds
described as data (``config/worlds/*.yaml``)."""
