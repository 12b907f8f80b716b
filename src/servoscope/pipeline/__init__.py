"""Pipeline: what runs the stages together for one video, above markers, camera and angle.

The stages below it flow one way (video → markers → camera → angle, see
docs/architecture.md and tests/test_architecture.py); what needs several of them
at once lives here:

* :mod:`.tracker` (:func:`track_video`): a markers engine over the video, then the
  frame checks, the camera stage (undistortion, the blade's plane, a rolling
  shutter's row times), the angle stage (the rigid-blade check, the angle, extra
  markers' bending, reference stickers) and the LED's t0;
* :mod:`.plane_view`: a track's view of the blade's plane from the stickers' shapes
  (the oblique-view warning, ``--self-calibrate-plane``);
* :mod:`.overlay`: an overlay video, the track drawn on the recorded footage
  (through the lens model and the plane back to the recorded pixels).

Only the tracker's names are imported here (a Dask worker unpickling
:func:`track_video` imports this package: it stays light); the other two are
imported by their module paths.
"""

from ..markers.settings import TrackerSettings
from ..markers.track import Track
from .tracker import track_video

__all__ = ["Track", "TrackerSettings", "track_video"]
