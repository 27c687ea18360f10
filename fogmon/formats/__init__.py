"""The file formats fogmon writes and reads (docs/formats.md): the replay log as CSV
(``replay_log``) and as Parquet (``parquet_log``), the recording in memory both give
(``recording``), the raw-capture sidecar (``capture``) and the archive folder layout
(``archive``). A floor: it imports neither fogmon.sources nor fogmon.sinks."""
