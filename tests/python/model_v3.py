"""An independent implementation of ../shared/spec/MODEL.md (spec v3),
written from the spec alone (standard library only), to check the raw
samples that `lightpose simulate` writes.

    python model_v3.py SCENE.toml TRAJ.csv OUT.json

computes every sample of every frame of the scene along the trajectory,
noise off: roll, several blinking beacons (phase, drift, off_s), channel
skew, daylight with its listed flicker components (its random part must be
off, random_std = 0: it is statistical). It writes a JSON object:

    {"n": N, "frames": [{"t": first sample's time,
                         "samples": [25 lists of N counts],
                         "doubt": [[k, i], ...]}, ...]}

`doubt` lists the samples whose exact value sits within 1e-6 counts of a
rounding boundary, or whose instant sits within 1e-9 of a square wave's
edge or an off_s bound: there two correct implementations may differ.
"""

import json
import math
import sys
import tomllib

ROWS = COLS = 5
NDET = ROWS * COLS


def spline(ts, ys):
    """Natural cubic spline through (ts, ys): second derivatives at knots."""
    n = len(ts)
    m = [0.0] * n
    if n > 2:
        # Tridiagonal system for the interior second derivatives.
        a = [0.0] * n
        b = [0.0] * n
        c = [0.0] * n
        d = [0.0] * n
        for i in range(1, n - 1):
            h0 = ts[i] - ts[i - 1]
            h1 = ts[i + 1] - ts[i]
            a[i] = h0
            b[i] = 2.0 * (h0 + h1)
            c[i] = h1
            d[i] = 6.0 * ((ys[i + 1] - ys[i]) / h1 - (ys[i] - ys[i - 1]) / h0)
        for i in range(2, n - 1):
            w = a[i] / b[i - 1]
            b[i] -= w * c[i - 1]
            d[i] -= w * d[i - 1]
        m[n - 2] = d[n - 2] / b[n - 2]
        for i in range(n - 3, 0, -1):
            m[i] = (d[i] - c[i] * m[i + 1]) / b[i]
    return m


def spline_at(ts, ys, m, t):
    """Value at t; outside the knots the end piece, extended."""
    n = len(ts)
    i = 0
    while i < n - 2 and t >= ts[i + 1]:
        i += 1
    h = ts[i + 1] - ts[i]
    a = (ts[i + 1] - t) / h
    b = (t - ts[i]) / h
    return (a * ys[i] + b * ys[i + 1]
            + ((a ** 3 - a) * m[i] + (b ** 3 - b) * m[i + 1]) * h * h / 6.0)


def read_trajectory(path):
    with open(path) as f:
        lines = [l.strip() for l in f if l.strip() and not l.startswith("#")]
    cols = lines[0].split(",")
    rows = [[float(v) for v in l.split(",")] for l in lines[1:]]
    ts = [r[0] for r in rows]
    table = {}
    for j, name in enumerate(cols[1:], start=1):
        ys = [r[j] for r in rows]
        if name in ("pitch", "yaw", "roll"):
            ys = [math.radians(y) for y in ys]
        table[name] = (ys, spline(ts, ys))
    if "roll" not in table:
        table["roll"] = ([0.0] * len(ts), [0.0] * len(ts))
    return ts, table


def matmul(a, b):
    return [[sum(a[i][k] * b[k][j] for k in range(3)) for j in range(3)]
            for i in range(3)]


def r_bv(roll, pitch, yaw):
    """R0 · Rz(ψ) · Ry(θ) · Rx(φ), R0 = diag(−1, 1, −1)."""
    r0 = [[-1, 0, 0], [0, 1, 0], [0, 0, -1]]
    cz, sz = math.cos(yaw), math.sin(yaw)
    cy, sy = math.cos(pitch), math.sin(pitch)
    cx, sx = math.cos(roll), math.sin(roll)
    rz = [[cz, -sz, 0], [sz, cz, 0], [0, 0, 1]]
    ry = [[cy, 0, sy], [0, 1, 0], [-sy, 0, cy]]
    rx = [[1, 0, 0], [0, cx, -sx], [0, sx, cx]]
    return matmul(matmul(matmul(r0, rz), ry), rx)


def apply(r, v):
    return [sum(r[i][k] * v[k] for k in range(3)) for i in range(3)]


def dot(a, b):
    return a[0] * b[0] + a[1] * b[1] + a[2] * b[2]


def angle(a, b):
    """The angle between a and b, through atan2 (precise near 0)."""
    c = [a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]]
    return math.atan2(math.sqrt(dot(c, c)), dot(a, b))


def response(beta, sigma):
    return math.exp(-beta * beta / (2 * sigma * sigma)) if beta < math.pi / 2 else 0.0


def per_channel(v, default):
    if v is None:
        return [default] * NDET
    if isinstance(v, list):
        return [float(x) for x in v]
    return [float(v)] * NDET


class Model:
    def __init__(self, scene):
        arr = scene.get("array", {})
        delta = math.radians(arr.get("spacing_deg", 15.0))
        self.radius = arr.get("radius_m", 0.229)
        self.sigma_r = math.radians(arr.get("sigma_r_deg", 18.0))
        self.gain = per_channel(arr.get("gain"), 1.0)
        self.offset = per_channel(arr.get("offset_v"), 0.15)
        self.normals = []
        for r in range(ROWS):
            for c in range(COLS):
                e, a = (2 - r) * delta, (c - 2) * delta
                self.normals.append([math.cos(e) * math.cos(a),
                                     math.cos(e) * math.sin(a), -math.sin(e)])
        water = scene.get("water", {})
        self.k_d = water.get("k_d", 0.09)
        temp = water.get("temp_c", 20.0)
        self.g_t = (576 - 2 * temp) / (576 - 2 * 20.0)
        sc = scene.get("scattering")
        self.scatter = None
        if sc is not None:
            self.scatter = (sc.get("omega", 0.5), math.radians(sc.get("sigma_h_deg", 20.0)))
        adc = scene.get("adc", {})
        self.bits = adc.get("bits", 10)
        self.v_ref = adc.get("v_ref", 5.0)
        self.rate = adc.get("rate_hz", 5.0)
        self.sample_hz = adc.get("sample_hz", self.rate)
        self.skew = adc.get("channel_skew_s", 0.0)
        self.n = round(self.sample_hz / self.rate)
        self.beacons = []
        if "beacons" in scene:
            for b in scene["beacons"]:
                ap = math.radians(b.get("axis_pitch_deg", 0.0))
                ay = math.radians(b.get("axis_yaw_deg", 0.0))
                self.beacons.append(self.beacon(b, b.get("position_m", [0, 0, 0]),
                                                [math.cos(ap) * math.cos(ay),
                                                 math.cos(ap) * math.sin(ay), math.sin(ap)]))
        else:
            self.beacons.append(self.beacon(scene.get("beacon", {}), [0, 0, 0], [1, 0, 0]))
        self.day = scene.get("daylight")
        if self.day is not None and self.day.get("random_std", 0.3) != 0:
            sys.exit("model_v3.py: the flicker's random part is statistical; set random_std = 0")

    @staticmethod
    def beacon(b, pos, axis):
        return {
            "v1": b.get("v1", 135.0),
            "sigma_b": math.radians(b.get("sigma_b_deg", 12.0)),
            "f": b.get("mod_hz", 0.0),
            "phase": b.get("phase_deg", 0.0),
            "drift": b.get("drift_ppm", 0.0),
            "off": b.get("off_s", []),
            "c": [float(x) for x in pos],
            "axis": axis,
        }

    @staticmethod
    def lit(b, t):
        """s_b(t), and whether t is within 1e-9 of an edge."""
        near = any(abs(t - a) < 1e-9 or abs(t - z) < 1e-9 for a, z in b["off"])
        if any(a <= t < z for a, z in b["off"]):
            return 0.0, near
        if b["f"] <= 0:
            return 1.0, near
        x = b["f"] * (1 + b["drift"] * 1e-6) * t + b["phase"] / 360.0
        frac = x - math.floor(x)
        near = near or min(frac, abs(frac - 0.5), 1 - frac) < 1e-9
        return (1.0 if frac < 0.5 else 0.0), near

    def irradiance(self, b, n, pk):
        r = [pk[i] - b["c"][i] for i in range(3)]
        d = math.sqrt(dot(r, r))
        alpha = angle(b["axis"], r)
        beta = angle(n, [-x for x in r])
        beam = math.exp(-alpha * alpha / (2 * b["sigma_b"] ** 2))
        path = math.exp(-self.k_d * d) / (d * d)
        direct = response(beta, self.sigma_r)
        if self.scatter is None:
            bracket = direct
        else:
            omega, sigma_h = self.scatter
            f = 1 - math.exp(-omega * self.k_d * d)
            st2 = self.sigma_r ** 2 + sigma_h ** 2
            bracket = (1 - f) * direct + f * (self.sigma_r ** 2 / st2) * response(beta, math.sqrt(st2))
        return b["v1"] * beam * path * bracket

    def ambient(self, n, pk, t):
        d = self.day
        s = d.get("surface_v", 1.0)
        h = d.get("origin_depth_m", 5.0) - pk[2]
        rho = d.get("upwelling", 0.02)
        hf = d.get("flicker_depth_m", 3.0)
        u = n[2]
        a = (1 - rho) * (1 + u) ** 2 / 4 + rho
        phi = sum(c.get("amplitude", 0.0) * math.sin(2 * math.pi * c.get("hz", 1.0) * t
                                                     + math.radians(c.get("phase_deg", 0.0)))
                  for c in d.get("flicker", []))
        flick = max(0.0, 1 + math.exp(-h / hf) * phi)
        return s * math.exp(-self.k_d * h) * a * flick

    def sample(self, traj, k, t):
        ts, tab = traj
        q = {name: spline_at(ts, ys, m, t) for name, (ys, m) in tab.items()}
        rot = r_bv(q["roll"], q["pitch"], q["yaw"])
        n = apply(rot, self.normals[k])
        pk = [q["x"] + self.radius * n[0], q["y"] + self.radius * n[1], q["z"] + self.radius * n[2]]
        light, doubt = 0.0, False
        for b in self.beacons:
            s, near = self.lit(b, t)
            doubt = doubt or near
            if s:
                light += self.irradiance(b, n, pk)
        if self.day is not None:
            light += self.ambient(n, pk, t)
        v = self.gain[k] * self.g_t * light + self.offset[k]
        fs = 2 ** self.bits - 1
        x = v / self.v_ref * fs
        frac = abs(x) - math.floor(abs(x))
        doubt = doubt or abs(frac - 0.5) < 1e-6
        c = math.floor(abs(x) + 0.5) * (1 if x >= 0 else -1)  # half away from zero
        return min(max(int(c), 0), fs), doubt


def main():
    scene_path, traj_path, out_path = sys.argv[1:4]
    with open(scene_path, "rb") as f:
        model = Model(tomllib.load(f))
    traj = read_trajectory(traj_path)
    ts = traj[0]
    t0, t_end = ts[0], ts[-1]
    half = (model.n - 1) / (2 * model.sample_hz)
    frames = []
    j = 0
    while t0 + j / model.rate + half <= t_end + 1e-9:
        first = t0 + j / model.rate
        samples = [[0] * model.n for _ in range(NDET)]
        doubt = []
        for i in range(model.n):
            for k in range(NDET):
                t = first + i / model.sample_hz + k * model.skew
                samples[k][i], d = model.sample(traj, k, t)
                if d:
                    doubt.append([k, i])
        frames.append({"t": first, "samples": samples, "doubt": doubt})
        j += 1
    with open(out_path, "w") as f:
        json.dump({"n": model.n, "frames": frames}, f)


if __name__ == "__main__":
    main()
