"""Peers run on the suite's bags: what a user would pick instead of lili_odom.

Each module exposes ``run(bag, context) -> PeerRun`` with base_link poses in the peer's
odometry frame (see :mod:`lili_odom.suite.frames`):

* :mod:`.kiss`: KISS-ICP's own pipeline (``KissICP.register_frame``), its default config;
* :mod:`.genz`: GenZ-ICP, its pre-tuned preset chosen by the kind of scene (:data:`.genz.PRESETS`);
* :mod:`.rko`: RKO-LIO through its Python API, with the bag's IMU and extrinsics;
* :mod:`.wheels`: the bag's wheel odometry poses.

The peer packages (``genz-icp``, ``rko-lio``) are the optional ``peers`` extra; a missing one
makes its rows fail with the reason, never the suite.
"""
PEERS = ("kiss", "genz", "rko", "wheels")
