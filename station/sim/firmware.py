"""The simulated unit's calibration firmware: Algorithm 1 from the EEPROM image, as the real unit runs it.

:class:`CalibrationFirmware` is a :data:`~station.sim.sensor_core.Corrector` for a simulated
sensor (a :class:`~station.sim.sensor_core.SensorUnit`: the pty peer or the in-process fake). At
every power-on (its ``reset()``, which the sensor calls at boot) it reads both EEPROM slots (and both
layout-2 slots, :data:`~station.eeprom.image.WIDE_SLOTS`), picks the valid image with
the highest update count (:func:`station.eeprom.image.select_image`) and loads Algorithm 1
of Kolhoff & Kemper with it. In CORRECTED output mode the sensor passes it each chunk of
raw samples; it returns them corrected: drift ``b_drift g_i`` (eq. 3, forward Euler),
static bias, one-sided moving average (eq. 6), ``M^-1`` (eq. 1), and, if the image has a
non-zero gyro g-sensitivity G, ``w -= M_w^-1 G a`` with the corrected specific force a. A
layout-2 image's time offset enters line 0 (the raw input moved onto the rig's time: a delay line with linear
interpolation for a lead, linear extrapolation for a lag; the batch engine carries that many more raw rows of
history); its temperature terms and scale nonlinearity (layout 3: the IEEE 952 polynomial) enter line 6' of
Algorithm 1
(:mod:`station.correct.streaming`) at the unit's own temperature reading of each sample (the
sensor passes its temperature column: :attr:`CalibrationFirmware.takes_temperature`).
Without a valid image (or with one for another serial) the output stays raw.

Two engines give the same output to rounding: ``"streaming"``
(:class:`~station.correct.StreamingCorrector`, sample by sample) and ``"batch"``
(:func:`~station.correct.correct_batch` per chunk, with the last n - 1 raw samples
carried as history so chunk boundaries are seamless).

Sample index: a real unit runs the correction on every sample from power-on. The
sensor calls the corrector only for samples sent in CORRECTED mode, so the firmware
places each chunk on the sample index from the clock (``(now - t_boot) / T_sampl``):
the first corrected chunk, or one after a gap of more than ``resync_s``, restarts the
moving average there with ``g = (1 - T_sampl/T_c)^index``.
"""

from __future__ import annotations

import math
from typing import Literal

import numpy as np

from station.correct import CorrectionConstants, StreamingCorrector, correct_batch
from station.eeprom.image import (
    DEFAULT_SLOTS,
    WIDE_SLOTS,
    CalibrationImage,
    SlotLayout,
    SlotState,
    read_slots,
    select_image,
)
from station.kernel.clock import Clock, WallClock
from station.kernel.parameters import ParameterSet
from station.sim.eeprom import Eeprom, EepromError
from station.sim.sensor_core import SensorUnit

Engine = Literal["streaming", "batch"]


class CalibrationFirmware:
    """Corrector that loads the unit's EEPROM image at power-on and runs Algorithm 1.

    Args:
        eeprom: the unit's EEPROM.
        clock: the sensor's clock (places chunks on the sample index since power-on).
        serial: only images for this serial are used (None: any).
        layout: where the two image slots lie.
        engine: ``"streaming"`` or ``"batch"`` (same output to rounding).
        resync_s: a jump of more than this between expected and clock-derived sample time
            restarts the correction at the clock's index (s).
    """

    def __init__(
        self,
        eeprom: Eeprom,
        clock: Clock | None = None,
        *,
        serial: str | None = None,
        layout: SlotLayout = DEFAULT_SLOTS,
        engine: Engine = "streaming",
        resync_s: float = 1.0,
    ) -> None:
        if engine not in ("streaming", "batch"):
            raise ValueError(f"engine must be 'streaming' or 'batch', not {engine!r}")
        self._eeprom = eeprom
        self._clock: Clock = clock if clock is not None else WallClock()
        self.serial = serial
        self.layout = layout
        self.engine: Engine = engine
        self.resync_s = float(resync_s)
        self.image: CalibrationImage | None = None
        self.load_error = ""
        self.boots = 0
        self._params: ParameterSet | None = None
        self._shift_rows = 0  # line 0's delay (samples) of the loaded image
        self._g_sens: np.ndarray | None = None
        self._t_boot = self._clock.now()
        self._index: int | None = None  # sample index of the next expected corrected sample
        self._stream: StreamingCorrector | None = None
        self._hist_a = np.zeros((0, 3))
        self._hist_w = np.zeros((0, 3))
        self._hist_t = np.zeros(0)
        self.reset()

    # --- power-on -------------------------------------------------------------------------------

    def _read_region(self, layout: SlotLayout) -> list[SlotState]:
        try:
            raw = self._eeprom.read(layout.base, 2 * layout.slot_size)
        except EepromError:
            self._eeprom.power_reset()  # at power-on no write cycle can still be running
            raw = self._eeprom.read(layout.base, 2 * layout.slot_size)
        return read_slots(bytes(layout.base) + raw, layout)

    def _read_slots(self) -> list[SlotState]:
        """Both slots of the layout-1 region and, when the EEPROM holds it, of the layout-2 region."""
        slots = self._read_region(self.layout)
        if self.layout != WIDE_SLOTS and self._eeprom.size >= WIDE_SLOTS.end:
            slots += self._read_region(WIDE_SLOTS)
        return slots

    def reset(self) -> None:
        """Power-on: read the EEPROM, load the current image (or none), restart Algorithm 1 (g = 1)."""
        self.boots += 1
        self._t_boot = self._clock.now()
        self._index = None
        self.image, self._params, self._g_sens, self.load_error = None, None, None, ""
        try:
            slots = self._read_slots()
        except EepromError as exc:
            self.load_error = f"EEPROM unreadable: {exc}"
            return
        current = select_image(slots, self.serial)
        if current is None or current.image is None:
            self.load_error = "; ".join(f"slot {s.name}: {s.error or 'other serial'}" for s in slots)
            return
        params = current.image.to_params()
        try:
            StreamingCorrector(params)  # validates (invertible M, positive T_c) as the firmware's loader would
        except Exception as exc:  # a valid CRC with unusable values: stay raw
            self.load_error = f"image in slot {current.name} not usable: {exc}"
            return
        self.image, self._params = current.image, params
        self._shift_rows = CorrectionConstants.from_params(params).shift[0]
        g = np.asarray(current.image.g_sensitivity)
        if np.any(g != 0):
            self._g_sens = np.linalg.solve(np.asarray(current.image.gyro.misalignment), g)  # M_w^-1 G

    @property
    def loaded(self) -> bool:
        """A valid image is loaded: CORRECTED output is corrected."""
        return self._params is not None

    # --- the correction -------------------------------------------------------------------------

    def _restart(self, index: int) -> None:
        assert self._params is not None
        self._index = index
        self._stream = StreamingCorrector(self._params, start_index=index) if self.engine == "streaming" else None
        self._hist_a = np.zeros((0, 3))
        self._hist_w = np.zeros((0, 3))
        self._hist_t = np.zeros(0)

    #: The sensor passes each chunk's temperature column (degC) as a third argument.
    takes_temperature = True

    def __call__(
        self, accel: np.ndarray, gyro: np.ndarray, temp_degc: np.ndarray | None = None
    ) -> tuple[np.ndarray, np.ndarray]:
        """Correct one chunk of consecutive raw samples (n, 3) in m/s^2 and rad/s (temperature (n,) degC)."""
        if self._params is None:
            return accel, gyro
        a = np.asarray(accel, dtype=np.float64)
        w = np.asarray(gyro, dtype=np.float64)
        n = a.shape[0]
        if n == 0:
            return a, w
        temp = None
        if self._params.compensates_temperature:
            if temp_degc is None:  # a caller without a temperature column: no temperature terms
                raise ValueError("the loaded image compensates temperature: the chunk's temperature is needed")
            temp = np.asarray(temp_degc, dtype=np.float64)
        ts = self._params.sample_period_s
        last = math.floor((self._clock.now() - self._t_boot) / ts + 1e-9)  # index of the newest sample
        first = max(0, last - n + 1)
        if self._index is None or abs(first - self._index) * ts > self.resync_s:
            self._restart(first)
        assert self._index is not None
        if self.engine == "streaming":
            assert self._stream is not None
            out_a, out_w = self._stream.run(a, w, temp)
        else:
            k = self._hist_a.shape[0]
            all_a = np.concatenate([self._hist_a, a])
            all_w = np.concatenate([self._hist_w, w])
            all_t = None if temp is None else np.concatenate([self._hist_t, temp])
            ca, cw = correct_batch(all_a, all_w, self._params, start_index=self._index - k, temp_degc=all_t)
            out_a, out_w = ca[k:], cw[k:]
            # history: the moving average's n - 1 rows and line 0's delay line (d rows) before them
            keep = self._params.moving_average_length - 1 + self._shift_rows
            self._hist_a = all_a[max(0, all_a.shape[0] - keep) :] if keep else np.zeros((0, 3))
            self._hist_w = all_w[max(0, all_w.shape[0] - keep) :] if keep else np.zeros((0, 3))
            if all_t is not None:
                self._hist_t = all_t[max(0, all_t.shape[0] - keep) :] if keep else np.zeros(0)
        self._index += n
        if self._g_sens is not None:
            out_w = out_w - out_a @ self._g_sens.T
        return out_a, out_w


def install_firmware(
    sensor: SensorUnit, clock: Clock | None = None, *, engine: Engine = "streaming"
) -> CalibrationFirmware:
    """Give ``sensor`` the calibration firmware (bound to its EEPROM and serial); returns it.

    The firmware loads the EEPROM now and takes now as its power-on time until the sensor's
    next boot (the sequence power-cycles every unit at its start, provisioning after the write).
    """
    fw = CalibrationFirmware(sensor.eeprom, clock, serial=sensor.identity.serial, engine=engine)
    sensor.corrector = fw
    return fw
