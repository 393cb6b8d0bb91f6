"""The calibration certificate of one unit and run: what it states, read from the station database.

:func:`unit_certificate` gathers, for a serial (and a run, default the unit's newest run with a verdict
and a parameter set), everything the certificate states: the parameter set with expanded uncertainties
(k = 2), each parameter's limit verdict, the verification on the rig, the limits file (name, version,
content hash) and its decision rule, station, rig, host, operator, lot, date, the verdict, and the
SHA-256 of the stored parameter set (``parameter_sets.sha256``, the hash of ``params_json``'s UTF-8 bytes:
the same file the run wrote), recomputed here and refused when it does not match.

Rendering (HTML: :mod:`station.store.certificate_html`, PDF: :mod:`station.store.certificate_pdf`) only
formats these typed values, in the display convention of :mod:`station.kernel.display`.
"""

from __future__ import annotations

import hashlib
import math
from dataclasses import dataclass
from datetime import UTC, datetime

import numpy as np
from sqlalchemy import select

from station.kernel.display import Display, display_for, display_of_check, format_number
from station.kernel.errors import StationError
from station.kernel.found_terms import found_terms
from station.kernel.limits import GUARD_BAND
from station.kernel.limits_file import LimitsFile, load_limits
from station.kernel.parameters import ParameterSet, TriadParams
from station.store.db import Database
from station.store.models import (
    UNFINISHED,
    Disposition,
    EepromWrite,
    LimitCheck,
    ParameterSetRecord,
    Run,
    RunUnit,
    Unit,
)
from station.store.models import Station as StationRow

__all__ = ["COVERAGE_K", "Certificate", "CertificateError", "CertificateParameter", "CertificateRecordError",
           "CertificateResult",
           "decision_rule_text", "unit_certificate"]

#: The coverage factor of the expanded uncertainties the certificate states (about 95 % for a normal law).
COVERAGE_K = 2.0
_AXES = "xyz"
_TRIADS = (("accel", "accelerometer"), ("gyro", "gyroscope"))
#: Verdicts of a unit that a certificate is issued for (the unit was measured and judged).
_JUDGED = ("PASS", "FAIL", "RETEST")


class CertificateError(StationError):
    """No certificate can be issued: unknown unit or run, no parameter set, no verdict."""


class CertificateRecordError(CertificateError):
    """The stored parameter set does not match its recorded SHA-256: the record was altered."""


@dataclass(frozen=True)
class CertificateParameter:
    """One calibrated parameter: its value and expanded uncertainty in SI and as shown, and its verdict.

    ``name`` is the stored name (``accel.M.xy``, ``gyro.bias_static.z``; the limit checks use the same);
    ``value_si``/``u_si`` the value and its *standard* uncertainty as stored (``u_si`` NaN: none);
    ``expanded_si`` = k u. ``verdict`` is the limit check's (PASS, MARGINAL, INCONCLUSIVE, FAIL) or "" when
    the parameter has no limit. ``display`` is how it is shown.
    """

    name: str
    group: str
    label: str
    value_si: float
    u_si: float
    si_unit: str
    low_si: float | None
    high_si: float | None
    verdict: str
    display: Display

    @property
    def expanded_si(self) -> float:
        return COVERAGE_K * self.u_si

    def shown(self) -> str:
        """``value ± U unit`` (U = k u, k = 2) in the display unit; "—" for a value the data did not determine."""
        return self.display.format(self.value_si, self.u_si if math.isfinite(self.u_si) else None, k=COVERAGE_K)

    def shown_limits(self) -> str:
        lo = self.display.value(self.low_si) if self.low_si is not None else None
        hi = self.display.value(self.high_si) if self.high_si is not None else None
        if lo is None and hi is None:
            return ""
        return f"[{format_number(lo)}, {format_number(hi)}] {self.display.unit}".rstrip()


@dataclass(frozen=True)
class CertificateResult:
    """A recorded check shown on the certificate (verification on the rig, fit quality): value against limits."""

    name: str
    value_si: float | None
    low_si: float | None
    high_si: float | None
    si_unit: str
    passed: bool
    verdict: str
    display: Display

    def shown(self) -> str:
        return self.display.format(self.value_si)

    def shown_limits(self) -> str:
        lo = self.display.value(self.low_si) if self.low_si is not None and math.isfinite(self.low_si) else None
        hi = self.display.value(self.high_si) if self.high_si is not None and math.isfinite(self.high_si) else None
        return f"[{format_number(lo)}, {format_number(hi)}] {self.display.unit}".rstrip()


@dataclass(frozen=True)
class Certificate:
    """Everything one calibration certificate states (see the module docstring)."""

    serial: str
    run_id: str
    verdict: str
    verdict_reason: str
    run_outcome: str
    station: str
    slot: int
    rig: str
    host: str
    sensor_url: str
    operator: str
    lot: str
    started_at: datetime
    finished_at: datetime | None
    software_version: str
    sequence_version: str
    sequence_hash: str
    limits_version: str
    limits_hash: str
    decision_rule: str
    params_format: str
    params_sha256: str
    sample_period_s: float
    reference_temperature_degc: float
    gravity_mps2: float | None
    parameters: tuple[CertificateParameter, ...]
    verification: tuple[CertificateResult, ...]
    fit_quality: tuple[CertificateResult, ...]
    checks_total: int
    checks_failed: int
    eeprom_image_sha256: str
    eeprom_verified: bool | None
    disposition: str
    issued_at: datetime

    def parameter(self, name: str) -> CertificateParameter:
        """The row of the stored parameter ``name`` (KeyError if the certificate has none)."""
        for p in self.parameters:
            if p.name == name:
                return p
        raise KeyError(name)


def _utc(t: datetime | None) -> datetime | None:
    if t is None:
        return None
    return t.replace(tzinfo=UTC) if t.tzinfo is None else t.astimezone(UTC)


def _triad_rows(key: str, group: str, t: TriadParams) -> list[tuple[str, str, float, float, str]]:
    """(name, label, value, std, SI unit) of one triad's parameters, the names the limit checks use."""
    si = "m/s^2" if key == "accel" else "rad/s"
    rows: list[tuple[str, str, float, float, str]] = []
    m, ms = np.asarray(t.misalignment), np.asarray(t.misalignment_std)
    for i, a in enumerate(_AXES):
        rows.append((f"{key}.M.{a}{a}", f"scale-factor error {a}", float(m[i, i]), float(ms[i, i]), "1"))
    for i, a in enumerate(_AXES):
        for j, b in enumerate(_AXES):
            if i != j:
                rows.append((f"{key}.M.{a}{b}", f"cross-axis {a}←{b}", float(m[i, j]), float(ms[i, j]), "1"))
    for field, label in (("bias_static", "static bias b_stat"), ("bias_drift", "drift bias b_drift (eq. 3)"),
                         ("noise_std", "white noise σ per sample"), ("drift_noise", "drift noise σ (eq. 3)")):
        v, s = np.asarray(getattr(t, field)), np.asarray(getattr(t, f"{field}_std"))
        rows += [(f"{key}.{field}.{a}", f"{label} {a}", float(v[i]), float(s[i]), si) for i, a in enumerate(_AXES)]
    tc, tcs = np.asarray(t.correlation_time_s), np.asarray(t.correlation_time_s_std)
    rows += [(f"{key}.correlation_time_s.{a}", f"drift correlation time T_c {a}", float(tc[i]), float(tcs[i]), "s")
             for i, a in enumerate(_AXES)]
    tb, tbs = np.asarray(t.temp_bias_coeff), np.asarray(t.temp_bias_coeff_std)
    tsc, tss = np.asarray(t.temp_scale_coeff), np.asarray(t.temp_scale_coeff_std)
    if tb.shape[1] and np.any(tb[:, 0]):
        rows += [(f"{key}.temp_bias_coeff.{a}", f"bias temperature coefficient {a}", float(tb[i, 0]),
                  float(tbs[i, 0]), f"{si}/K") for i, a in enumerate(_AXES)]
    if tsc.shape[1] and np.any(tsc[:, 0]):
        rows += [(f"{key}.temp_scale_coeff.{a}", f"scale temperature coefficient {a}", float(tsc[i, 0]),
                  float(tss[i, 0]), "1/K") for i, a in enumerate(_AXES)]
    if key == "gyro":
        g, gs = np.asarray(t.g_sensitivity), np.asarray(t.g_sensitivity_std)
        if np.any(g):
            rows += [(f"gyro.g_sensitivity.{a}{b}", f"g-sensitivity {a}←{b}", float(g[i, j]), float(gs[i, j]),
                      "rad/s/(m/s^2)") for i, a in enumerate(_AXES) for j, b in enumerate(_AXES)]
        k, ks = np.asarray(t.scale_nonlinearity), np.asarray(t.scale_nonlinearity_std)
        if np.any(k):
            rows += [(f"gyro.scale_nonlinearity.{a}", f"scale nonlinearity k {a} (u + k u|u|)", float(k[i]),
                      float(ks[i]), "1/(rad/s)") for i, a in enumerate(_AXES)]
    return rows


def _display(name: str, si_unit: str) -> Display:
    if si_unit == "rad/s/(m/s^2)":
        return display_for("g_sensitivity")
    if si_unit == "1/(rad/s)":
        return display_for("nonlinearity")
    return display_of_check(name, si_unit)


def _parameters(params: ParameterSet, checks: dict[str, LimitCheck]) -> list[CertificateParameter]:
    out: list[CertificateParameter] = []
    for key, group in _TRIADS:
        for name, label, value, std, unit in _triad_rows(key, group, getattr(params, key)):
            c = checks.get(name)
            verdict = (c.verdict or ("PASS" if c.passed else "FAIL")) if c is not None else ""
            out.append(CertificateParameter(
                name, group, label, value, std if math.isfinite(std) and std > 0 else math.nan, unit,
                c.low if c is not None else None, c.high if c is not None else None, verdict, _display(name, unit)))
    # the found terms: a kept one with its value, one the fit estimated but the recording did not determine as "—"
    # (not determined: no number); a term the fit did not try, or estimated and not kept, has no row
    labels = {"k2": "scale polynomial k2 {a} ({std}, u²)", "k3": "scale polynomial k3 {a} ({std}, u³)"}
    found = found_terms(params)
    for t in found.polynomial:
        if t.status in ("fitted", "not_determined"):
            triad, term, a = t.name.split(".")
            group, standard = ("gyroscope", "IEEE 952") if triad == "gyro" else ("accelerometer", "IEEE 1293")
            out.append(CertificateParameter(t.name, group, labels[term].format(a=a, std=standard), t.value, t.std,
                                            t.unit, None, None, "", _display(t.name, t.unit)))
    t = found.time_offset
    if t.status in ("fitted", "not_determined"):
        out.append(CertificateParameter("time_offset_s", "timing", "time offset (unit minus rig)", t.value,
                                        t.std, "s", None, None, "", _display("time_offset_s", "s")))
    return out


def _result(c: LimitCheck) -> CertificateResult:
    return CertificateResult(c.name, c.value, c.low, c.high, c.unit, c.passed,
                             c.verdict or ("PASS" if c.passed else "FAIL"), display_of_check(c.name, c.unit))


def decision_rule_text(limits: LimitsFile | None, ks: set[float]) -> str:
    """The decision rule in words: from the limits file when it is the one the run used, else from the checks."""
    if limits is not None:
        p = limits.product
        if p.rule == GUARD_BAND:
            text = (f"ISO 14253-1 guard bands (JCGM 106) with the expanded uncertainty U = k·u, k = {p.k_sigma:g}: "
                    "a parameter conforms (PASS) when value ± U lies inside its limits; it does not conform (FAIL) "
                    "when the value lies outside them; when the value lies inside but value ± U reaches beyond a "
                    f"limit, conformance is not proven (INCONCLUSIVE, which this limits file rates as "
                    f"{p.inconclusive.upper()}).")
        else:
            text = (f"widened limits (station-limits/1): a parameter passes when it lies within its limits widened "
                    f"by k·u, k = {p.k_sigma:g} (not the ISO 14253-1 guard-band rule).")
        if p.plausibility:
            families = ", ".join(sorted(p.plausibility))
            text += (f" The families {families} describe the sensor class rather than a property "
                     f"the calibration delivers and are judged for plausibility: within their range widened by "
                     f"{p.plausibility_k:g}·u.")
        return text + (" A PASS within the limits file's marginal fraction of the range width of a limit is "
                       "MARGINAL (still a pass).")
    shown = ", ".join(f"{k:g}" for k in sorted(ks)) or "none recorded"
    return ("The limits file the run used is not at hand to state its rule; the verdicts are those recorded with "
            f"each parameter (coverage factors used: {shown}). Under the default limits file the rule is ISO "
            "14253-1 guard bands with k = 2.")


def _limits_of_run(limits_hash: str, candidates: tuple[LimitsFile, ...]) -> LimitsFile | None:
    for lim in candidates:
        if lim.sha256 == limits_hash:
            return lim
    return None


def unit_certificate(db: Database, serial: str, run_id: str | None = None, *,
                     limits_files: tuple[LimitsFile, ...] | None = None) -> Certificate:
    """The certificate of ``serial`` in ``run_id`` (default: its newest finished run with a verdict and a
    parameter set). ``limits_files``: limits files to state the decision rule from, the one whose content hash
    is the run's (default: the station's default limits file). Raises :class:`CertificateError`."""
    if limits_files is None:
        try:
            limits_files = (load_limits(),)
        except StationError:
            limits_files = ()
    with db.transaction() as s:
        unit = s.scalar(select(Unit).where(Unit.serial == serial))
        if unit is None:
            raise CertificateError(f"no unit with serial {serial!r}")
        q = (select(RunUnit, Run, StationRow.name, ParameterSetRecord)
             .join(Run, RunUnit.run_id == Run.id).join(StationRow, Run.station_id == StationRow.id)
             .join(ParameterSetRecord, ParameterSetRecord.run_unit_id == RunUnit.id)
             .where(RunUnit.unit_id == unit.id, Run.outcome != UNFINISHED))
        q = q.where(Run.run_uid == run_id) if run_id is not None else q.where(RunUnit.outcome.in_(_JUDGED))
        row = s.execute(q.order_by(Run.started_at.desc(), Run.id.desc(), ParameterSetRecord.id.desc()).limit(1)).first()
        if row is None:
            what = f"run {run_id!r}" if run_id is not None else "a finished run with a verdict"
            raise CertificateError(f"unit {serial!r} has no parameter set from {what}")
        ru, run, station_name, rec = row
        if ru.outcome not in _JUDGED:
            raise CertificateError(f"unit {serial!r} in run {run.run_uid}: {ru.outcome}; a certificate needs a "
                                   "verdict (PASS, FAIL or RETEST)")
        checks = list(s.scalars(select(LimitCheck).where(LimitCheck.run_unit_id == ru.id).order_by(LimitCheck.id)))
        write = s.scalar(select(EepromWrite).where(EepromWrite.run_unit_id == ru.id).order_by(EepromWrite.id.desc())
                         .limit(1))
        disp = s.scalar(select(Disposition).where(Disposition.unit_id == unit.id)
                        .order_by(Disposition.decided_at.desc(), Disposition.id.desc()).limit(1))
        stored_sha, text, fmt = rec.sha256, rec.params_json, rec.format
        run_fields = (run.run_uid, run.outcome, run.rig, run.host, run.operator, run.lot or "", _utc(run.started_at),
                      _utc(run.finished_at), run.software_version, run.sequence_version, run.sequence_hash,
                      run.limits_version, run.limits_hash)
        ru_fields = (ru.outcome, ru.message, ru.slot, ru.sensor_url)
        eeprom = (write.image_sha256, bool(write.verified)) if write is not None else ("", None)
        disposition = (f"{disp.decision} by {disp.operator or '-'}: {disp.note}" if disp is not None else "")
    computed = hashlib.sha256(text.encode("utf-8")).hexdigest()
    if computed != stored_sha:
        raise CertificateRecordError(f"the stored parameter set of {serial!r} in run {run_fields[0]} does not "
                                     f"match its recorded SHA-256 ({stored_sha[:16]}... recorded, {computed[:16]}... "
                                     "computed): "
                                     "the record was altered; no certificate is issued")
    params = ParameterSet.from_json(text)
    (rid, run_outcome, rig, host, operator, lot, started, finished, software, seq_v, seq_h, lim_v, lim_h) = run_fields
    product = {c.name: c for c in checks if c.step == "limits" and not c.name.startswith("fit.")}
    verification = tuple(_result(c) for c in checks if c.step == "verify")
    fit_quality = tuple(_result(c) for c in checks if c.step == "limits" and c.name.startswith("fit."))
    ks = {float(c.k) for c in checks if c.k}
    gravity = params.source.get("gravity_mps2")
    assert started is not None
    return Certificate(
        serial=serial, run_id=rid, verdict=ru_fields[0], verdict_reason=ru_fields[1], run_outcome=run_outcome,
        station=station_name, slot=ru_fields[2], rig=rig, host=host, sensor_url=ru_fields[3], operator=operator,
        lot=lot, started_at=started, finished_at=finished, software_version=software, sequence_version=seq_v,
        sequence_hash=seq_h, limits_version=lim_v, limits_hash=lim_h,
        decision_rule=decision_rule_text(_limits_of_run(lim_h, tuple(limits_files)), ks),
        params_format=fmt, params_sha256=stored_sha, sample_period_s=float(params.sample_period_s),
        reference_temperature_degc=float(params.reference_temperature_degc),
        gravity_mps2=float(gravity) if isinstance(gravity, (int, float)) else None,
        parameters=tuple(_parameters(params, product)), verification=verification, fit_quality=fit_quality,
        checks_total=len(checks), checks_failed=sum(1 for c in checks if not c.passed),
        eeprom_image_sha256=eeprom[0], eeprom_verified=eeprom[1], disposition=disposition,
        issued_at=datetime.now(UTC),
    )
