"""Live model check (docs/modelcheck.md): the model's DADEV band for the live window
(``band``, cached on disk by ``cache``) and the watcher that turns each window's ADEV
into ``model_band`` events and a session summary, with the aux samples of each window
(``watch``)."""
from fogmon.modelcheck.band import ModelBand
from fogmon.modelcheck.watch import AuxWindows, ModelWatch

__all__ = ["AuxWindows", "ModelBand", "ModelWatch"]
