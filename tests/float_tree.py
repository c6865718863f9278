"""An independent floating-point whole-tree Jacobian (finite differences of plain forward kinematics),
used only to cross-check :mod:`identcheck.certify.tree_rank`'s exact verdicts in tests."""
import numpy as np
from scipy.spatial.transform import Rotation


def _unit(az, el):
    return np.array([np.cos(el) * np.cos(az), np.cos(el) * np.sin(az), np.sin(el)])


class FloatTree:
    def __init__(self, spec, n_frames, seed=0):
        self.spec, self.N = spec, n_frames
        rng = np.random.default_rng(seed)
        self.markers = [m for ms in spec.markers.values() for m in ms]
        const = []
        for m in self.markers:
            const += list(rng.normal(size=3))
        for name, kind, _, _ in spec.joints:
            const += list(rng.normal(size=3))
            if kind == "revolute":
                const += list(rng.uniform(-3, 3, size=2))
        self.n_const = len(const)
        per = 6 + sum(3 if k == "spherical" else 1 for _, k, _, _ in spec.joints)
        self.x0 = np.concatenate([const, rng.normal(size=per * n_frames)])
        self.per = per

    def unpack(self, x):
        i = 0
        m = {}
        for name in self.markers:
            m[name] = x[i:i + 3]; i += 3
        c, a = {}, {}
        for name, kind, _, _ in self.spec.joints:
            c[name] = x[i:i + 3]; i += 3
            if kind == "revolute":
                a[name] = _unit(*x[i:i + 2]); i += 2
        return m, c, a, x[self.n_const:].reshape(self.N, self.per)

    def positions(self, x):
        m, c, a, v = self.unpack(x)
        out = []
        for f in range(self.N):
            k = 6
            pose = {self.spec.root: (Rotation.from_rotvec(v[f, :3]).as_matrix(), v[f, 3:6])}
            for name, kind, par, chi in self.spec.joints:
                R, t = pose[par]
                if kind == "spherical":
                    Q = Rotation.from_rotvec(v[f, k:k + 3]).as_matrix(); k += 3
                else:
                    Q = Rotation.from_rotvec(a[name] * v[f, k]).as_matrix(); k += 1
                pose[chi] = (R @ Q, R @ c[name] + t)
            for s, ms in self.spec.markers.items():
                R, t = pose[s]
                out += [R @ m[n] + t for n in ms]
        return np.concatenate(out) if out else np.zeros(0)

    def jacobian(self, fn, x, h=1e-6):
        cols = []
        for i in range(len(x)):
            e = np.zeros_like(x); e[i] = h
            cols.append((fn(x + e) - fn(x - e)) / (2 * h))
        return np.array(cols).T

    def distances(self, joint):
        """Squared marker-to-centre (spherical) or marker-to-axis (revolute) distances of the adjacent markers."""
        name, kind, par, chi = next(j for j in self.spec.joints if j[0] == joint)

        def f(x):
            m, c, a, _ = self.unpack(x)
            vals = []
            for n in self.spec.markers[par]:
                w = m[n] - c[name]
                vals.append(w @ w - ((w @ a[name]) ** 2 if kind == "revolute" else 0))
            for n in self.spec.markers[chi]:
                w = m[n]
                vals.append(w @ w - ((w @ a[name]) ** 2 if kind == "revolute" else 0))
            return np.array(vals)
        return f

    def centre_distance(self, a, b):
        """Squared distance between the centres of two ball joints with the same parent segment."""
        def f(x):
            _, c, _, _ = self.unpack(x)
            w = c[a] - c[b]
            return np.array([w @ w])
        return f

    def locally_identifiable(self, joint, tol=1e-5):
        return self.determined(self.distances(joint), tol)

    def determined(self, fn, tol=1e-5):
        """Is every component of ``fn`` (a function of the parameter vector) locally determined by the markers?"""
        J = self.jacobian(self.positions, self.x0)
        G = self.jacobian(fn, self.x0)
        if G.size == 0:
            return False
        U, s, Vt = np.linalg.svd(J, full_matrices=False)
        r = int(np.sum(s > 1e-7 * s[0]))
        V = Vt[:r]                                       # row space of J
        res = G - (G @ V.T) @ V
        return bool(np.all(np.linalg.norm(res, axis=1) <= tol * np.maximum(np.linalg.norm(G, axis=1), 1e-12)))
