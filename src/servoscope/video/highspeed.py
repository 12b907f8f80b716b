"""High-speed cameras' raw files: Photron MRAW (+ CIH/CIHX header) and Phantom CINE.

Optional: ``pip install servoscope[highspeed]`` brings ``pyMRAW`` (Photron's
header) and ``pims`` (Phantom's CINE reader). Headers are read as the camera
wrote them:

* **Photron**: the frame rate is the record rate divided by the save step
  (CIHX ``skipFrame``, CIH ``Save Step`` / ``Skip Frame``): a recording at
  15,000 frames/s saved every 100th frame is 150 frames/s. The bit depth is
  the *effective* one (12-bit sensors store 16-bit words, or pack two samples
  in three bytes); the trigger time is ``startFrame / record rate`` (the
  first saved frame's place from the trigger). Frames are read one at a time
  from the MRAW at their offset (pyMRAW itself loads a 12-bit file whole).
* **Phantom**: the setup's frame rate is the *recording* rate; a CINE saved
  with a step (decimation) holds every ``n``-th frame, which only its
  per-frame timestamps tell: the step is ``round(rate · median interval)``
  (the pims sample ``cine_781``: 90,000 frames/s saved every 10th, 9,000
  frames/s). The bit depth is ``RealBPP``; the trigger time is the first
  frame's time to the trigger. Colour CINEs are not read yet.
"""

from __future__ import annotations

import xml.etree.ElementTree as ET

from pathlib import Path

import numpy as np

from ..errors import ServoscopeError
from .frame_source import SourceHeader, SourceSpec, regular_times

__all__ = ["PhotronMraw", "PhantomCine", "read_cih", "unpack_12bit"]

_EXTRA = "pip install 'servoscope[highspeed]'"


def _need(module: str, what: str):
    import importlib

    try:
        return importlib.import_module(module)
    except ImportError:
        raise ServoscopeError(f"reading {what} needs the {module} package: {_EXTRA}") from None


def _find_header(mraw: Path) -> Path:
    for suffix in (".cihx", ".cih"):
        candidate = mraw.with_suffix(suffix)
        if candidate.is_file():
            return candidate
    raise ServoscopeError(f"{mraw}: Photron MRAW without its header ({mraw.with_suffix('.cihx').name} or "
                          f"{mraw.with_suffix('.cih').name} beside it): its frame size, rate and bit depth are "
                          "only there")


def _cihx_extra(path: Path) -> dict:
    """CIHX fields pyMRAW leaves out: save step, start frame, colour type."""
    text = path.read_bytes().decode("utf-8", errors="ignore")
    start, end = text.find("<cih>"), text.rfind("</cih>")
    root = ET.fromstring(text[start:end + len("</cih>")])

    def get(where: str, default: str) -> str:
        node = root.find(where)
        return node.text.strip() if node is not None and node.text else default

    return {"save_step": int(get("frameInfo/skipFrame", "1")), "start_frame": int(get("frameInfo/startFrame", "0")),
            "colour_type": get("imageDataInfo/colorInfo/type", "Mono")}


def read_cih(path: str | Path) -> dict:
    """A Photron CIH or CIHX header: pyMRAW's fields plus save step, start frame and colour type.

    Returns
    -------
    dict
        pyMRAW's keys (``"Record Rate(fps)"``, ``"Total Frame"``, ``"Image Width"``,
        ``"Color Bit"``, ``"EffectiveBit Depth"``, …) and ``"save_step"``,
        ``"start_frame"``, ``"colour_type"``.

    Raises
    ------
    ServoscopeError
        When the header is unreadable or lacks a field.
    """
    path = Path(path)
    pymraw = _need("pyMRAW", "Photron MRAW files")
    try:
        cih = dict(pymraw.get_cih(str(path)))
        if path.suffix.lower() == ".cihx":
            cih.update(_cihx_extra(path))
        else:
            cih["save_step"] = int(cih.get("Save Step", cih.get("Skip Frame", 1)))
            cih["start_frame"] = int(cih.get("Start Frame", 0))
            cih["colour_type"] = str(cih.get("Color Type", "Mono"))
        for key in ("Record Rate(fps)", "Total Frame", "Image Width", "Image Height", "Color Bit"):
            cih[key] = float(cih[key]) if key == "Record Rate(fps)" else int(cih[key])
    except (KeyError, ValueError, TypeError, IndexError, ET.ParseError, OSError) as exc:
        raise ServoscopeError(f"{path}: not a readable Photron header ({type(exc).__name__}: {exc})") from None
    return cih


def unpack_12bit(data: np.ndarray) -> np.ndarray:
    """Photron's packed 12-bit samples (two in three bytes, big-endian nibbles) as uint16."""
    b = data.reshape(-1, 3).astype(np.uint16)
    out = np.empty((b.shape[0], 2), np.uint16)
    out[:, 0] = (b[:, 0] << 4) | (b[:, 1] >> 4)
    out[:, 1] = ((b[:, 1] & 0x0F) << 8) | b[:, 2]
    return out.reshape(-1)


class PhotronMraw:
    """A Photron MRAW file (``.mraw``, or its ``.cih``/``.cihx`` header) as a frame source.

    Raises
    ------
    ServoscopeError
        No header beside the MRAW, no MRAW beside the header, a file shorter
        than its header says, a colour type servoscope does not read.
    """

    def __init__(self, spec: SourceSpec):
        given = Path(spec.path)
        if given.suffix.lower() == ".mraw":
            if not given.is_file():
                raise ServoscopeError(f"{given}: no such file")
            self.mraw, header = given, _find_header(given)
        else:
            if not given.is_file():
                raise ServoscopeError(f"{given}: no such file")
            self.mraw, header = given.with_suffix(".mraw"), given
            if not self.mraw.is_file():
                raise ServoscopeError(f"{given}: Photron header without its {self.mraw.name}")
        cih = read_cih(header)
        self.cih = cih
        self.width, self.height = cih["Image Width"], cih["Image Height"]
        self.word_bits = cih["Color Bit"]
        if self.word_bits not in (8, 12, 16):
            raise ServoscopeError(f"{header}: {self.word_bits}-bit samples; servoscope reads 8-, 12- and 16-bit MRAW")
        self.frame_bytes = self.width * self.height * self.word_bits // 8
        n = cih["Total Frame"]
        size = self.mraw.stat().st_size
        if size < n * self.frame_bytes:
            raise ServoscopeError(f"{self.mraw}: truncated: {size} bytes hold {size // self.frame_bytes} of the "
                                  f"{n} frames its header announces")
        effective = int(cih.get("EffectiveBit Depth", self.word_bits)) if self.word_bits == 16 else self.word_bits
        self.shift = 16 - effective if str(cih.get("EffectiveBit Side", "Lower")).lower() == "higher" else 0
        kind = str(cih["colour_type"]).lower()
        if kind == "raw" and spec.bayer is None:
            raise ServoscopeError(f"{header}: raw Bayer colour frames: give the sensor's Bayer pattern "
                                  "(--bayer RGGB, or bayer = … in the manifest)")
        if kind not in ("mono", "raw"):
            raise ServoscopeError(f"{header}: colour type {cih['colour_type']!r}; servoscope reads Mono and Raw (Bayer) MRAW")
        rate = cih["Record Rate(fps)"]
        step = max(1, int(cih["save_step"]))
        fps = rate / step
        said = f"header: record rate {rate:g} / save step {step}"
        if spec.fps is not None:
            fps, said = spec.fps, "command line or manifest (the header says " + f"{rate / step:g})"
        times, times_from = regular_times(spec, n, fps, said)
        self.header = SourceHeader(
            format="mraw", width=self.width, height=self.height, frame_count=n, frame_rate_hz=fps,
            frame_rate_from=said, bit_depth=effective,
            colour="monochrome" if kind == "mono" else f"raw Bayer {spec.bayer}",
            sample_format="packed 12-bit" if self.word_bits == 12 else f"uint{self.word_bits}",
            times_s=times, times_from=times_from, trigger_s=cih["start_frame"] / rate, files=(str(self.mraw),))
        self._file = open(self.mraw, "rb")

    def read(self, index: int) -> np.ndarray:
        """Frame ``index``'s samples (uint8, or uint16 in the low ``bit_depth`` bits)."""
        self._file.seek(index * self.frame_bytes)
        raw = np.frombuffer(self._file.read(self.frame_bytes), np.uint8)
        if raw.size != self.frame_bytes:
            raise ServoscopeError(f"{self.mraw}: frame {index} is cut short")
        if self.word_bits == 8:
            return raw.reshape(self.height, self.width).copy()
        if self.word_bits == 12:
            return unpack_12bit(raw).reshape(self.height, self.width)
        data = raw.view("<u2").reshape(self.height, self.width)
        return (data >> self.shift) if self.shift else data.copy()

    def close(self) -> None:
        """Close the MRAW file."""
        self._file.close()


class PhantomCine:
    """A Phantom CINE file as a frame source (read with pims).

    Raises
    ------
    ServoscopeError
        A file pims cannot open, a truncated file (a frame's offset beyond
        its end), a colour or compressed CINE.
    """

    def __init__(self, spec: SourceSpec):
        path = Path(spec.path)
        if not path.is_file():
            raise ServoscopeError(f"{path}: no such file")
        pims = _need("pims", "Phantom CINE files")
        import struct

        try:
            self.cine = pims.open(str(path))
        except (struct.error, ValueError, OSError, KeyError, IndexError) as exc:
            raise ServoscopeError(f"{path}: not a readable Phantom CINE, or truncated ({type(exc).__name__}: "
                                  f"{exc})") from None
        c = self.cine
        self.path = path
        n = len(c)
        size = path.stat().st_size
        image_bytes = int(c.bitmapinfo_dict["bi_image_size"])
        locations = [int(x) for x in c.image_locations]
        cut = [k for k, at in enumerate(locations) if at + 8 + image_bytes > size]
        if cut:
            c.close()
            raise ServoscopeError(f"{path}: truncated: frames {cut[0]} to {n - 1} of {n} lie beyond the end of the "
                                  f"file ({size} bytes)")
        setup = c.setup_fields_dict
        if int(setup.get("cfa", 0)) or int(setup.get("b_enable_color", 0)) or c.compression:
            c.close()
            raise ServoscopeError(f"{path}: a colour or compressed CINE; servoscope reads monochrome, uncompressed ones")
        rate = float(c.frame_rate)
        stamps = np.array([d.timestamp() + f for d, f in c.frame_time_stamps])  # whole seconds + fraction
        step = 1
        if n > 1:
            step = max(1, int(round(rate * float(np.median(np.diff(stamps))))))
        fps = rate / step
        said = f"header: frame rate {rate:g}" + (f" / save step {step} (from the frames' timestamps)" if step > 1 else "")
        if spec.fps is not None:
            fps, said = spec.fps, f"command line or manifest (the header says {rate / step:g})"
        times, times_from = regular_times(spec, n, fps, said)
        self.header = SourceHeader(
            format="cine", width=int(c.frame_shape[1]), height=int(c.frame_shape[0]), frame_count=n,
            frame_rate_hz=fps, frame_rate_from=said, bit_depth=int(setup.get("real_bpp", 8 * np.dtype(c.pixel_type).itemsize)),
            colour="monochrome", sample_format=str(np.dtype(c.pixel_type)), times_s=times, times_from=times_from,
            trigger_s=float(c.get_time_to_trigger(0)), files=(str(path),))
        self.camera_times_s = stamps - stamps[0]

    def read(self, index: int) -> np.ndarray:
        """Frame ``index``'s samples as pims gives them (uint16 for 12/14-bit cameras)."""
        return np.asarray(self.cine.get_frame(index))

    def close(self) -> None:
        """Close the CINE file."""
        self.cine.close()
