"""Peer for tubeloc's calibration interchange test (calib/tests/integration/interchange_peer.rs).

  interchange_peer.py JOB.json    prints JSON with the pixels each written file projects to

JOB.json: {"opencv": {"file": F, "points_rig": [[x, y, z], ...]},
           "ros": [{"file": F, "points_cam": [[x, y, z], ...]}, ...],
           "ros_pairs": [{"left": F, "right": F, "points_left": [...], "points_right": [...]}, ...],
           "kalibr": {"file": F, "points_cam0": [[x, y, z], ...]}}

- OpenCV FileStorage YAML: read with cv2.FileStorage; each camera's K, D, R, T applied by
  cv2.projectPoints to rig-frame points.
- ROS camera_info: read with PyYAML; K, D applied by cv2.projectPoints to camera-frame points;
  for each stereo pair, the rectified pixels in ROS's convention: the 3D point in the pair's
  stereo frame (the left camera's R times the left-camera point) projected with each file's P,
  and the right camera's own rectified ray P_right[:, :3] (R_right X_right).
- kalibr camchain: read with PyYAML, checked with kalibr's own type rules, and projected with the
  pinhole-radtan equations written out here (points given in cam0, carried down the chain by
  T_cn_cnm1).
Exit code 3 when cv2, numpy or yaml is not installed.
"""
import json
import sys

try:
    import cv2
    import numpy as np
    import yaml
except ImportError as e:
    print(f"missing Python module: {e}", file=sys.stderr)
    sys.exit(3)


def opencv(job):
    fs = cv2.FileStorage(job["file"], cv2.FILE_STORAGE_READ)
    if not fs.isOpened():
        raise SystemExit(f"cv2.FileStorage cannot open {job['file']}")
    pts = np.array(job["points_rig"], dtype=np.float64).reshape(-1, 1, 3)
    out = {}
    for i in range(int(fs.getNode("camera_count").real())):
        name = fs.getNode(f"cam{i}_name").string()
        k = fs.getNode(f"cam{i}_camera_matrix").mat()
        d = fs.getNode(f"cam{i}_distortion_coefficients").mat()
        r = fs.getNode(f"cam{i}_R").mat()
        t = fs.getNode(f"cam{i}_T").mat()
        rvec, _ = cv2.Rodrigues(r)
        px, _ = cv2.projectPoints(pts, rvec, t, k, d)
        out[name] = px.reshape(-1, 2).tolist()
    fs.release()
    return out


def ros(job):
    with open(job["file"]) as f:
        info = yaml.safe_load(f)
    assert info["distortion_model"] == "plumb_bob", info["distortion_model"]
    k = np.array(info["camera_matrix"]["data"], dtype=np.float64).reshape(3, 3)
    d = np.array(info["distortion_coefficients"]["data"], dtype=np.float64)
    r = np.array(info["rectification_matrix"]["data"], dtype=np.float64).reshape(3, 3)
    p = np.array(info["projection_matrix"]["data"], dtype=np.float64).reshape(3, 4)
    pts = np.array(job["points_cam"], dtype=np.float64)
    px, _ = cv2.projectPoints(pts.reshape(-1, 1, 3), np.zeros(3), np.zeros(3), k, d)
    return {"name": info["camera_name"], "size": [info["image_width"], info["image_height"]], "pixels": px.reshape(-1, 2).tolist()}


def read_rp(path):
    with open(path) as f:
        info = yaml.safe_load(f)
    r = np.array(info["rectification_matrix"]["data"], dtype=np.float64).reshape(3, 3)
    p = np.array(info["projection_matrix"]["data"], dtype=np.float64).reshape(3, 4)
    return r, p


def project_h(p, pts):
    h = (p @ np.vstack([pts.T, np.ones(len(pts))])).T
    return (h[:, :2] / h[:, 2:3]).tolist()


def ros_pair(job):
    rl, pl = read_rp(job["left"])
    rr, pr = read_rp(job["right"])
    xl = np.array(job["points_left"], dtype=np.float64)
    xr = np.array(job["points_right"], dtype=np.float64)
    stereo = (rl @ xl.T).T
    own = (rr @ xr.T).T
    own_px = (pr[:, :3] @ own.T).T
    return {"left": project_h(pl, stereo), "right": project_h(pr, stereo), "right_own": (own_px[:, :2] / own_px[:, 2:3]).tolist()}


def radtan_project(intr, dist, p):
    fu, fv, pu, pv = intr
    k1, k2, r1, r2 = dist
    x, y = p[0] / p[2], p[1] / p[2]
    mx2, my2, mxy = x * x, y * y, x * y
    rho2 = mx2 + my2
    rad = k1 * rho2 + k2 * rho2 * rho2
    xd = x + x * rad + 2.0 * r1 * mxy + r2 * (rho2 + 2.0 * mx2)
    yd = y + y * rad + 2.0 * r2 * mxy + r1 * (rho2 + 2.0 * my2)
    return [fu * xd + pu, fv * yd + pv]


def kalibr(job):
    with open(job["file"]) as f:
        chain = yaml.safe_load(f)
    out = {}
    t_cn_c0 = np.eye(4)
    n = 0
    while f"cam{n}" in chain:
        cam = chain[f"cam{n}"]
        # kalibr's CameraParameters checks (ConfigReader.py): float intrinsics, int resolution.
        assert cam["camera_model"] == "pinhole" and cam["distortion_model"] == "radtan", cam
        assert len(cam["intrinsics"]) == 4 and all(isinstance(v, float) for v in cam["intrinsics"]), cam["intrinsics"]
        assert len(cam["distortion_coeffs"]) == 4, cam["distortion_coeffs"]
        assert len(cam["resolution"]) == 2 and all(isinstance(v, int) for v in cam["resolution"]), cam["resolution"]
        assert isinstance(cam["rostopic"], str)
        if n > 0:
            t = np.array(cam["T_cn_cnm1"], dtype=np.float64)
            assert t.shape == (4, 4)
            t_cn_c0 = t @ t_cn_c0
        pixels = []
        for p in job["points_cam0"]:
            pc = t_cn_c0 @ np.array([p[0], p[1], p[2], 1.0])
            pixels.append(radtan_project(cam["intrinsics"], cam["distortion_coeffs"], pc[:3]))
        out[f"cam{n}"] = pixels
        n += 1
    return out


def main():
    with open(sys.argv[1]) as f:
        job = json.load(f)
    result = {"opencv": opencv(job["opencv"]), "ros": [ros(r) for r in job["ros"]], "ros_pairs": [ros_pair(r) for r in job["ros_pairs"]], "kalibr": kalibr(job["kalibr"]), "cv2_version": cv2.__version__}
    print(json.dumps(result))


if __name__ == "__main__":
    main()
