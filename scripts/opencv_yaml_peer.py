"""OpenCV FileStorage peer for tubeloc's rig YAML.

  opencv_yaml_peer.py write OUT.yaml   writes a two-camera rig with cv2.FileStorage
  opencv_yaml_peer.py read IN.yaml     reads a tubeloc-written rig with cv2.FileStorage and
                                       prints its fields as JSON
Exit code 3 when cv2 is not installed.
"""
import json
import sys

try:
    import cv2
    import numpy as np
except ImportError:
    sys.exit(3)

CAMS = [("L20", 0.0), ("R20", -0.2)]


def write(path):
    fs = cv2.FileStorage(path, cv2.FILE_STORAGE_WRITE)
    fs.write("camera_count", len(CAMS))
    fs.startWriteStruct("stereo_pairs", cv2.FileNode_SEQ | cv2.FileNode_FLOW)
    for n, _ in CAMS:
        fs.write("", n)
    fs.endWriteStruct()
    for i, (n, tx) in enumerate(CAMS):
        fs.write(f"cam{i}_name", n)
        fs.write(f"cam{i}_image_width", 1368)
        fs.write(f"cam{i}_image_height", 912)
        fs.write(f"cam{i}_camera_matrix", np.array([[860.0 + i, 0, 683.5], [0, 861.0 + i, 455.5], [0, 0, 1]]))
        fs.write(f"cam{i}_distortion_coefficients", np.array([[-0.1, 0.01, 0.001, -0.002, 0.0005]]))
        c, s = np.cos(0.01 * i), np.sin(0.01 * i)
        fs.write(f"cam{i}_R", np.array([[c, 0, s], [0, 1, 0], [-s, 0, c]]))
        fs.write(f"cam{i}_T", np.array([[tx], [0.001], [0.002]]))
    fs.release()


def read(path):
    fs = cv2.FileStorage(path, cv2.FILE_STORAGE_READ)
    n = int(fs.getNode("camera_count").real())
    out = {"camera_count": n, "cameras": []}
    for i in range(n):
        g = lambda k: fs.getNode(f"cam{i}_{k}")
        out["cameras"].append({
            "name": g("name").string(),
            "width": int(g("image_width").real()),
            "K": g("camera_matrix").mat().tolist(),
            "D": g("distortion_coefficients").mat().ravel().tolist(),
            "R": g("R").mat().tolist(),
            "T": g("T").mat().ravel().tolist(),
        })
    print(json.dumps(out))


if __name__ == "__main__":
    {"write": write, "read": read}[sys.argv[1]](sys.argv[2])
