"""The simulator: a sensor model (``model``: TOML file, effect catalogue) turned into
samples (``simulate``: batch and streaming) from exact IEEE-952 noise generators
(``noise``), physical effects as pure functions (``effects``) and generated aux
channels (``scenarios``: MWD run, thermal chamber, orbit). See docs/sim.md."""
