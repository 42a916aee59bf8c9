"""The scenario suite: scenarios as data (``scenario``), run by our methods and the peers."""
