"""The monitor's Rerun output: ``sink`` (RerunSink), ``blueprint`` (its entities and
default layout), ``style`` (colours), ``columns`` (what it sends in columns), ``server``
(the gRPC server process of --serve) and ``plots`` (labelled 2-D plots, also drawn by
fogmon.explain). Nothing is imported here, so importing ``plots`` does not import the sink.
"""
