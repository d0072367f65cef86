#!/usr/bin/env python3
"""Reference outputs of the real MediaPipe for facelab's landmarker tests.

Runs once, offline, with the mediapipe 0.10.14 wheel and tflite-runtime (Python 3.11):

    pip install mediapipe==0.10.14 tflite-runtime pillow numpy
    python3 tools/landmarker/reference.py /path/to/mediapipe/modules tests/data/landmarker

`tests/data/landmarker/photos/*.png` are the committed test photos (SOURCES.md there). For
each it writes, in `tests/data/landmarker/reference/`:

- `<photo>.detection.csv`: MediaPipe's short-range face detector (FaceDetection,
  model_selection=0): `face,score,xmin,ymin,width,height` in pixels, then the six keypoints
  `kp0_x..kp5_y` in pixels; no rows when it finds no face;
- `<photo>.landmarks.csv`: Face Mesh (FaceMesh, static_image_mode=True,
  refine_landmarks=False, max_num_faces=1): `vertex,x,y,z`, x and y in pixels, z scaled like
  x (MediaPipe's normalized z times the image width); no rows when it finds no face.

And the networks alone, on a fixed input given by a formula (so no image resampling is
involved), from the TFLite interpreter on the wheel's own .tflite files:
`network_<name>.csv` with `output,index,value` for every output value. The input pattern is
`pattern(h, w, c) = sin(0.37 h + 0.11 w + 1.3 c) * cos(0.05 (h - w))` in [-1, 1], the range both
networks take; `facelab::landmark` tests build the same tensor.
"""

import csv
import math
import sys
from pathlib import Path

import mediapipe as mp
import numpy as np
from PIL import Image
from tflite_runtime.interpreter import Interpreter

NETWORKS = {
    "face_detection_short_range": "face_detection/face_detection_short_range.tflite",
    "face_landmark": "face_landmark/face_landmark.tflite",
}


def pattern(size):
    h, w, c = np.meshgrid(np.arange(size), np.arange(size), np.arange(3), indexing="ij")
    return (np.sin(0.37 * h + 0.11 * w + 1.3 * c) * np.cos(0.05 * (h - w))).astype(np.float32)


def networks(modules, out):
    for name, rel in NETWORKS.items():
        it = Interpreter(model_path=str(modules / rel))
        it.allocate_tensors()
        inp = it.get_input_details()[0]
        size = int(inp["shape"][1])
        it.set_tensor(inp["index"], pattern(size)[None])
        it.invoke()
        with open(out / f"network_{name}.csv", "w", newline="") as f:
            w = csv.writer(f, lineterminator="\n")
            w.writerow(["output", "index", "value"])
            for d in it.get_output_details():
                for i, v in enumerate(it.get_tensor(d["index"]).reshape(-1)):
                    w.writerow([d["name"], i, f"{v:.6g}"])


def photos(photo_dir, out):
    detector = mp.solutions.face_detection.FaceDetection(model_selection=0, min_detection_confidence=0.5)
    mesh = mp.solutions.face_mesh.FaceMesh(static_image_mode=True, refine_landmarks=False, max_num_faces=1)
    for path in sorted(photo_dir.glob("*.png")):
        rgb = np.asarray(Image.open(path).convert("RGB"))
        height, width = rgb.shape[:2]
        det = detector.process(rgb)
        with open(out / f"{path.stem}.detection.csv", "w", newline="") as f:
            w = csv.writer(f, lineterminator="\n")
            w.writerow(["face", "score", "xmin", "ymin", "width", "height"]
                       + [f"kp{k}_{a}" for k in range(6) for a in "xy"])
            for i, d in enumerate(det.detections or []):
                box = d.location_data.relative_bounding_box
                kps = d.location_data.relative_keypoints
                w.writerow([i, f"{d.score[0]:.6g}", f"{box.xmin * width:.4f}", f"{box.ymin * height:.4f}",
                            f"{box.width * width:.4f}", f"{box.height * height:.4f}"]
                           + [f"{v:.4f}" for k in kps for v in (k.x * width, k.y * height)])
        res = mesh.process(rgb)
        with open(out / f"{path.stem}.landmarks.csv", "w", newline="") as f:
            w = csv.writer(f, lineterminator="\n")
            w.writerow(["vertex", "x", "y", "z"])
            if res.multi_face_landmarks:
                for i, p in enumerate(res.multi_face_landmarks[0].landmark):
                    w.writerow([i, f"{p.x * width:.4f}", f"{p.y * height:.4f}", f"{p.z * width:.4f}"])
        found = "face" if res.multi_face_landmarks else "no face"
        print(f"{path.name}: {len(det.detections or [])} detections, mesh: {found}")


def main():
    if len(sys.argv) != 3:
        raise SystemExit(__doc__)
    modules, data = Path(sys.argv[1]), Path(sys.argv[2])
    out = data / "reference"
    out.mkdir(parents=True, exist_ok=True)
    networks(modules, out)
    photos(data / "photos", out)


if __name__ == "__main__":
    main()
