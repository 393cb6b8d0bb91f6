"""The unit's calibration in its EEPROM: image layout, safe provisioning, post-calibration verification.

* :mod:`station.eeprom.image` - the versioned binary image (``layout.md``), encode/decode, A/B slots.
* :mod:`station.eeprom.provision` - page-by-page write through the sensor protocol, read-back, the runner's
  Provisioner.
* :mod:`station.sequence.verify` - the sensor's corrected output checked on the rig.
"""

from station.eeprom.image import (
    DEFAULT_SLOTS,
    IMAGE_SIZE,
    LAYOUT_VERSION,
    CalibrationImage,
    ImageContentError,
    ImageCrcError,
    ImageError,
    ImageLengthError,
    ImageMagicError,
    ImageVersionError,
    SlotLayout,
    decode_image,
    encode_image,
    select_image,
)

__all__ = [
    "DEFAULT_SLOTS",
    "IMAGE_SIZE",
    "LAYOUT_VERSION",
    "CalibrationImage",
    "ImageContentError",
    "ImageCrcError",
    "ImageError",
    "ImageLengthError",
    "ImageMagicError",
    "ImageVersionError",
    "SlotLayout",
    "decode_image",
    "encode_image",
    "select_image",
]
