"""Old import path of `fourierjax.io.model_io` (model and characteristic files), re-exported."""

from fourierjax.io.model_io import (
    CHARACTERISTIC_FORMAT_NAME,
    CHARACTERISTIC_FORMAT_VERSION,
    FORMAT_NAME,
    FORMAT_VERSION,
    ModelFile,
    ModelFileError,
    load_characteristic,
    load_model,
    save_characteristic,
    save_model,
)

__all__ = ["FORMAT_NAME", "FORMAT_VERSION", "CHARACTERISTIC_FORMAT_NAME",
           "CHARACTERISTIC_FORMAT_VERSION", "ModelFileError", "ModelFile", "save_model",
           "load_model", "save_characteristic", "load_characteristic"]
