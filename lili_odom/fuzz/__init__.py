"""Seeded fuzz campaign over every public input door of the package.

Doors (one module each, every case generated from ``(seed, door, index)`` alone, so any case can
be replayed by its number):

* ``clouds`` (:mod:`.clouds`): ``sensor_msgs/PointCloud2`` content into
  :func:`lili_odom.pointcloud2.parse_cloud`; documented error ``CloudFormatError``.
* ``api`` (:mod:`.api`): ``Scan``, ``ImuSample`` and ``WheelSample`` objects into
  :class:`~lili_odom.pipeline.odometry.OdometryPipeline`; documented error
  :class:`~lili_odom.pipeline.validation.PipelineInputError`.
* ``feeder`` (:mod:`.feeder`): duck-typed ROS messages on any topic into
  :class:`~lili_odom.pipeline.feeder.MessageFeeder`; no error may escape.
* ``bags`` (:mod:`.bags`): truncated, corrupt and mistyped rosbag2 bags into ``lili-odom run``;
  documented error :class:`~lili_odom.errors.UserError` (exit code 2, one line).
* ``detect`` (:mod:`.detect`): broken cloud and pose files and options into ``lili-odom detect``;
  documented error :class:`~lili_odom.errors.UserError`.
* ``sequences`` (:mod:`.sequences`): a few hundred scans of a real bag with sensor faults
  through the feeder and the pipeline (``lili`` and ``none``).

:mod:`.campaign` runs each door's cases in worker subprocesses (:mod:`.worker`), so a native
abort or a hang ends one case, not the campaign.
"""
