"""The streaming pipeline shared by `fogmon replay` and `fogmon monitor`: source ->
StreamingDadev -> fit_noise per completed window -> sinks. ``config``: what a run is asked
(PipelineConfig, the run's window and hop; the default window is fogmon.window's);
``run``: the Pipeline; ``axis``: one axis's analysis; ``reader``: the reader thread with
back-pressure; ``progress``: a replay's progress bar. The names callers use are
re-exported here.
"""
from fogmon.pipeline.axis import OVERALL_MAX_SAMPLES, AxisAnalysis
from fogmon.pipeline.config import PipelineConfig, TauSpec, live_samples, window_and_hop
from fogmon.pipeline.progress import ReplayProgress
from fogmon.pipeline.reader import QUEUE_MAX_SAMPLES
from fogmon.pipeline.run import ERROR_EXPR, Pipeline, run_pipeline
from fogmon.window import LIVE_WINDOW_SAMPLES, MAX_WINDOW_SAMPLES, MIN_WINDOW_SAMPLES, default_window_s

__all__ = [
    "ERROR_EXPR", "LIVE_WINDOW_SAMPLES", "MAX_WINDOW_SAMPLES", "MIN_WINDOW_SAMPLES", "OVERALL_MAX_SAMPLES",
    "QUEUE_MAX_SAMPLES", "AxisAnalysis", "Pipeline", "PipelineConfig", "ReplayProgress", "TauSpec",
    "default_window_s", "live_samples", "run_pipeline", "window_and_hop",
]
