"""File readers, each a module with ``open_source(path, opts) -> Source`` (``opts`` a
fogmon.sources.options.SourceOptions): replay logs as CSV (``replay_log``) and Parquet
(``parquet``), raw serial captures (``capture``), CAN logs (``can_log``), archive folders
(``archive``), and other tools' recordings: ROS bags and MCAP (``rosbag``), PX4 ULogs
(``ulog``), MDF4 (``mdf``), LAS (``las``), which share ``stamped`` (timestamped samples
on fogmon's grid). Which reader opens which file: the reader table of fogmon.sources.open."""
