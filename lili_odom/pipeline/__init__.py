"""The odometry pipeline (pure Python): the same object serves the node, the bag runner and the
benchmarks."""
