"""The track cache: exact round trips, keys, reuse, --force, and resuming a stopped run."""

from __future__ import annotations

import dataclasses
import hashlib
import shutil
from dataclasses import dataclass

import numpy as np
import pytest

from servoscope.campaign import cache as cache_module
from servoscope.campaign import load_campaign, parallel, track_campaign
from servoscope.campaign.cache import TrackCache, file_digest, tracks_equal
from servoscope.campaign.runner import _settings
from servoscope.markers.track import Track


def _synthetic_track(n: int = 7) -> Track:
    rng = np.random.default_rng(1)
    lead = rng.normal(300, 5, (n, 2))
    lead[2] = np.nan
    angle = rng.normal(0, 0.1, n)
    angle[2] = np.nan
    return Track(
        video="clip é.mp4",
        frame=np.arange(n),
        time_s=np.arange(n) / 100.0 + 1e-17,
        lead_xy_px=lead,
        trail_xy_px=rng.normal(100, 5, (n, 2)),
        lead_area_px=rng.uniform(50, 60, n),
        trail_area_px=rng.uniform(50, 60, n),
        angle_rad=angle,
        valid=np.array([True, True, False, True, True, True, True]),
        reason=["", "", "lead marker partly hidden (area 80 % of its reference) — ¼", "", "", "", ""],
        led_level=np.full(n, np.nan),
        t0_s=0.1234567890123456789,
        t0_uncertainty_s=float("nan"),
        warnings=["1 of 7 frames invalid"],
        snapshot_rgb=None,
        snapshot_index=3,
    )


def test_round_trip_gives_equal_tracks(quick_result, tmp_path):
    cache = TrackCache(tmp_path)
    tracks = {"synthetic": _synthetic_track(), **quick_result.tracks}
    for label, track in tracks.items():
        cache.store(f"k{label}", track)
        back = cache.load(f"k{label}")
        assert back is not None
        assert tracks_equal(back, track), label
        assert type(back.reason) is list and type(back.warnings) is tuple
    # The comparison itself is not vacuous.
    changed = dataclasses.replace(tracks["synthetic"], time_s=tracks["synthetic"].time_s.copy())
    changed.time_s[4] = np.nextafter(changed.time_s[4], 1.0)
    assert not tracks_equal(changed, tracks["synthetic"])
    assert not tracks_equal(dataclasses.replace(tracks["synthetic"], reason=[""] * 7), tracks["synthetic"])


def test_fields_added_to_track_round_trip(tmp_path, monkeypatch):
    @dataclass(frozen=True)  # Track is frozen: so is a class derived from it
    class TrackPlus(Track):  # what another engineer adding fields to Track would make
        spare_sigma_px: np.ndarray | None = None
        note: str = ""
        counts: list[int] = dataclasses.field(default_factory=list)

    base = _synthetic_track()
    plus = TrackPlus(**{f.name: getattr(base, f.name) for f in dataclasses.fields(Track)},
                     spare_sigma_px=np.linspace(0, 1, 7), note="n", counts=[1, 2])
    cache = TrackCache(tmp_path)
    cache.store("old", base)  # written before the fields existed
    monkeypatch.setattr(cache_module, "Track", TrackPlus)
    cache.store("new", plus)
    back = cache.load("new")
    assert isinstance(back, TrackPlus) and tracks_equal(back, plus)
    # An entry lacking the new fields is not what this code would produce: a miss.
    assert cache.load("old") is None


def test_damaged_or_foreign_entries_are_misses(tmp_path):
    cache = TrackCache(tmp_path)
    track = _synthetic_track()
    cache.store("a", track)
    npz, meta = cache.paths("a")
    npz.write_bytes(npz.read_bytes()[:100])  # truncated by a crash of another program
    assert cache.load("a") is None
    cache.store("b", track)
    npz, meta = cache.paths("b")
    meta.write_text(meta.read_text().replace('"cache_format": 1', '"cache_format": 999'))
    assert cache.load("b") is None
    cache.store("c", track)
    cache.paths("c")[1].unlink()  # the JSON is written last: without it the entry is incomplete
    assert cache.load("c") is None and "c" not in cache
    assert cache.load("never-stored") is None
    assert not list(cache.folder.glob("*.tmp*")), "temporary files left behind"


def test_file_digest_hashes_the_whole_file(tmp_path):
    data = np.random.default_rng(0).integers(0, 256, 2_500_000, dtype=np.uint8).tobytes()  # > 2 chunks
    path = tmp_path / "v.bin"
    path.write_bytes(data)
    assert file_digest(path) == hashlib.blake2b(data, digest_size=20).hexdigest()
    assert file_digest(path, chunk_bytes=4096) == file_digest(path)


def test_key_follows_content_and_settings_not_names(quick_campaign, tmp_path):
    campaign = load_campaign(quick_campaign)
    settings = _settings(campaign)
    cache = TrackCache(tmp_path / "cache")
    video = campaign.tests[-1].video
    key = cache.key(video, settings)
    copy = tmp_path / "renamed.mp4"
    shutil.copyfile(video, copy)
    assert cache.key(copy, settings) == key  # content, not name
    assert cache.key(video, dataclasses.replace(settings)) == key  # equal settings, equal key
    data = bytearray(copy.read_bytes())
    data[len(data) // 2] ^= 1  # one bit in the middle: a first/last-MiB hash would miss it
    copy.write_bytes(bytes(data))
    assert cache.key(copy, settings) != key
    k = settings.camera.camera_matrix.copy()
    k[0, 0] += 1e-9
    other_camera = dataclasses.replace(settings.camera, camera_matrix=k)
    for changed in (
        dataclasses.replace(settings, camera=other_camera),
        dataclasses.replace(settings, camera=None),
        dataclasses.replace(settings, led=None),
        dataclasses.replace(settings, lead="#ff0000"),
        dataclasses.replace(settings, exposure_s=0.005),
        dataclasses.replace(settings, search_radius_px=settings.search_radius_px + 1),
    ):
        assert cache.key(video, changed) != key, changed


@pytest.fixture
def two_video_campaign(quick_campaign):
    campaign = load_campaign(quick_campaign)
    return dataclasses.replace(campaign, tests=(campaign.tests[0], campaign.tests[-1]))


class _CountingTracker:
    """Stands in for track_video: returns the reference track of each video, counting calls."""

    def __init__(self, reference: dict[str, Track], stop_at: str | None = None):
        self.by_name = {t.video: t for t in reference.values()}
        self.calls: list[str] = []
        self.stop_at = stop_at

    def __call__(self, path, settings, *, progress=None):
        name = str(path).rsplit("/", 1)[-1]
        self.calls.append(name)
        if name == self.stop_at:
            raise KeyboardInterrupt  # Ctrl-C while this video is being tracked
        return self.by_name[name]


def test_second_run_tracks_nothing_and_force_tracks_again(two_video_campaign, quick_result, tmp_path, monkeypatch):
    cache_dir = tmp_path / ".cache"
    first = track_campaign(two_video_campaign, cache_dir=cache_dir)  # really tracked
    labels = [t.label for t in two_video_campaign.tests]
    for label in labels:
        assert tracks_equal(first[label], quick_result.tracks[label])
    fake = _CountingTracker(quick_result.tracks)
    monkeypatch.setattr(parallel, "track_video", fake)
    done = []
    second = track_campaign(two_video_campaign, cache_dir=cache_dir, on_done=lambda *a: done.append(a), workers=1)
    assert fake.calls == []
    assert done == [(label, "cached") for label in labels]
    assert list(second) == labels and all(tracks_equal(second[k], first[k]) for k in labels)
    track_campaign(two_video_campaign, cache_dir=cache_dir, force=True, workers=1)
    assert len(fake.calls) == 2


def test_a_stopped_run_resumes_with_the_unfinished_video(two_video_campaign, quick_result, tmp_path, monkeypatch):
    cache_dir = tmp_path / ".cache"
    first_video, second_video = (t.video.name for t in two_video_campaign.tests)
    stopped = _CountingTracker(quick_result.tracks, stop_at=second_video)
    monkeypatch.setattr(parallel, "track_video", stopped)
    with pytest.raises(KeyboardInterrupt):
        track_campaign(two_video_campaign, cache_dir=cache_dir, workers=1)
    assert stopped.calls == [first_video, second_video]
    cache = TrackCache(cache_dir)
    assert len(list(cache.folder.glob("*.json"))) == 1  # the finished video only
    # A half-written entry (a worker killed while saving) must not count either.
    settings = _settings(two_video_campaign)
    npz, _ = cache.paths(cache.key(two_video_campaign.tests[1].video, settings))
    npz.write_bytes(b"PK\x03\x04 half")
    resumed = _CountingTracker(quick_result.tracks)
    monkeypatch.setattr(parallel, "track_video", resumed)
    tracks = track_campaign(two_video_campaign, cache_dir=cache_dir, workers=1)
    assert resumed.calls == [second_video]
    for t in two_video_campaign.tests:
        assert tracks_equal(tracks[t.label], quick_result.tracks[t.label])
