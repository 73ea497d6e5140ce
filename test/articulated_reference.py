"""MODEL.md's tractor and semi-trailer rewritten for the tests, independent of the package's
model: the equations of "The whole vehicle" as a numpy right-hand side for
``scipy.integrate.solve_ivp``, and the level-road statics as a force and moment balance.

Nothing here imports ``road_force_estimator``: the parameters come in as a plain dict
(:func:`defaults`, MODEL.md's table), the road as a function of the distance.
"""
from __future__ import annotations

import numpy as np

G = 9.80665


def defaults() -> dict:
    """MODEL.md's European 5-axle 40 t combination (its tables), as plain numbers."""
    axles = []
    for name, body, xi, m, ia, s, w, k, c, kphi, kt, hrc, rho in (
            ('front', 't', 0.0, 900, 600, 0.45, 1.02, 400e3, 15e3, 0.2e6, 1000e3, 0.5, 0.5),
            ('drive', 't', 3.7, 1400, 800, 0.5, 0.92, 450e3, 20e3, 0.5e6, 2000e3, 0.7, 0.5),
            ('trailer_1', 'r', 9.6, 800, 450, 0.65, 1.02, 450e3, 15e3, 0.8e6, 1800e3, 0.6, 0.45),
            ('trailer_2', 'r', 10.91, 800, 450, 0.65, 1.02, 450e3, 15e3, 0.8e6, 1800e3, 0.6,
             0.45),
            ('trailer_3', 'r', 12.22, 800, 450, 0.65, 1.02, 450e3, 15e3, 0.8e6, 1800e3, 0.6,
             0.45)):
        axles.append(dict(name=name, body=body, xi=xi, m=m, ia=ia, s=s, w=w, k=k, c=c,
                          kphi=kphi, kt=kt, hrc=hrc, rho=rho))
    bodies = {'t': dict(M=6500.0, xi=1.1, iy=20000.0, ix=4000.0, H=1.1, h=0.6),
              'r': dict(M=29000.0, xi=8.6, iy=450000.0, ix=35000.0, H=2.0, h=1.4)}
    fifth = dict(xi=3.2, k=5e7, c=1e5, kphi=3e6, cphi=3e4)
    return dict(axles=axles, bodies=bodies, fifth=fifth)


def statics(p: dict) -> dict:
    """Level road, sides equal: each axle a spring 2k above the axle and its tires 2kt below,
    the axle's weight m g between them; the bodies' heave and pitch from the force and
    moment balance of each body (the fifth wheel a spring between them). With a body point
    sinking by ``s_j``: ``s_j = S_j / (2 k) + (S_j + m_j g) / (2 kt)``. Returns per axle the
    spring load S_j and the wheel load S_j + m_j g (N, both sides) and the kingpin load."""
    b, fw = p['bodies'], p['fifth']
    # unknowns: z_t, th_t, z_r, th_r (a body point at xi sinks by -(z + (xi - xi_b) th))
    kk = np.zeros((4, 4))
    f = np.array([-b['t']['M'] * G, 0.0, -b['r']['M'] * G, 0.0])
    col = {'t': 0, 'r': 2}
    rows = []
    for a in p['axles']:
        ke = 1.0 / (1.0 / (2 * a['k']) + 1.0 / (2 * a['kt']))
        i = col[a['body']]
        e = np.zeros(4)
        e[i], e[i + 1] = 1.0, a['xi'] - b[a['body']]['xi']
        kk += ke * np.outer(e, e)
        # S = ke (-(e x) - m g / (2 kt)): the constant part is a load on the body
        f -= ke * a['m'] * G / (2 * a['kt']) * e
        rows.append((e, ke, a))
    e5 = np.array([1.0, fw['xi'] - b['t']['xi'], -1.0, -(fw['xi'] - b['r']['xi'])])
    kk += fw['k'] * np.outer(e5, e5)
    x = np.linalg.solve(kk, f)
    springs = np.array([ke * (-(e @ x) - a['m'] * G / (2 * a['kt'])) for e, ke, a in rows])
    wheels = springs + np.array([a['m'] * G for a in p['axles']])
    return dict(spring=springs, wheel=wheels, kingpin=fw['k'] * float(e5 @ x))


class Reference:
    """d/dt of the state (MODEL.md's equations), coordinates as the package orders them:
    z_t, th_t, ph_t, z_r, th_r, ph_r, then z_a,j, ph_a,j per axle; then the rates. Arrays
    over the axles; the road is ``road(x (N,)) -> (N, 2)``."""

    def __init__(self, p: dict, road, distance, speed_accel, lateral, spring_load_n,
                 wheel_load_n):
        self.p = p
        self.road, self.distance = road, distance
        self.speed_accel, self.lateral = speed_accel, lateral
        ax = p['axles']
        self.N = len(ax)
        self.n = 6 + 2 * self.N
        col = lambda key: np.array([float(a[key]) for a in ax])  # noqa: E731
        self.xi, self.m, self.ia = col('xi'), col('m'), col('ia')
        self.s, self.w, self.k, self.c = col('s'), col('w'), col('k'), col('c')
        self.kphi, self.kt = col('kphi'), col('kt')
        self.bi = np.array([0 if a['body'] == 't' else 3 for a in ax])
        self.tr = self.bi == 0
        self.d = self.xi - np.array([p['bodies'][a['body']]['xi'] for a in ax])
        S = np.asarray(spring_load_n, float)
        self.lat = col('hrc') * S / G + col('rho') * self.m
        self.floor = -np.asarray(wheel_load_n, float) / 2     # per wheel, sides equal
        self.fc = np.asarray(wheel_load_n, float) / 2

    def forces(self, t: float, y: np.ndarray):
        """(q (N, 2), spring forces on the body (N, 2), tire forces (N, 2))."""
        n, bi = self.n, self.bi
        pos, vel = y[:n], y[n:]
        zb, thb, phb = pos[bi], pos[bi + 1], pos[bi + 2]
        vz, vth, vph = vel[bi], vel[bi + 1], vel[bi + 2]
        za, pa = pos[6::2], pos[7::2]
        vza, vpa = vel[6::2], vel[7::2]
        u = self.road(self.distance(t) - self.xi)
        sg = np.array([1.0, -1.0])
        q = (zb + self.d * np.sin(thb))[:, None] + sg * (self.s * np.sin(phb))[:, None] - (
            za[:, None] + sg * (self.s * np.sin(pa))[:, None])
        dq = (vz + self.d * np.cos(thb) * vth)[:, None] + sg * (
            self.s * np.cos(phb) * vph)[:, None] - (vza[:, None] + sg * (
                self.s * np.cos(pa) * vpa)[:, None])
        spring = -(self.k[:, None] * q + self.c[:, None] * dq)
        zw = za[:, None] + sg * (self.w * np.sin(pa))[:, None]
        tire = np.maximum(self.kt[:, None] * (u - zw), self.floor[:, None])
        return q, spring, tire

    def __call__(self, t: float, y: np.ndarray) -> np.ndarray:
        p, n = self.p, self.n
        pos, vel = y[:n], y[n:]
        ay, ax = self.lateral(t), self.speed_accel(t)
        fw, bodies = p['fifth'], p['bodies']
        _, spring, tire = self.forces(t, y)
        phb, pa = pos[self.bi + 2], pos[7::2]
        mar = -self.kphi * (phb - pa)
        fsum, fdiff = spring.sum(1), spring[:, 0] - spring[:, 1]
        acc = np.zeros(n)
        acc[6::2] = (-fsum + tire.sum(1)) / self.m
        acc[7::2] = (-self.s * np.cos(pa) * fdiff + self.w * np.cos(pa) * (tire[:, 0] - tire[:, 1])
                     - mar + self.lat * ay) / self.ia
        zt, tht, pht, zr, thr, phr = pos[:6]
        vzt, vtht, vpht, vzr, vthr, vphr = vel[:6]
        lt, lr = fw['xi'] - bodies['t']['xi'], fw['xi'] - bodies['r']['xi']
        delta = zt + lt * np.sin(tht) - zr - lr * np.sin(thr)
        ddelta = vzt + lt * np.cos(tht) * vtht - vzr - lr * np.cos(thr) * vthr
        f5 = -(fw['k'] * delta + fw['c'] * ddelta)
        m5 = -(fw['kphi'] * (pht - phr) + fw['cphi'] * (vpht - vphr))
        for bi, (key, sigma, lev, on) in enumerate((('t', 1.0, lt, self.tr),
                                                    ('r', -1.0, lr, ~self.tr))):
            bd = bodies[key]
            th, ph = pos[3 * bi + 1], pos[3 * bi + 2]
            acc[3 * bi] = (fsum[on].sum() + sigma * f5) / bd['M']
            acc[3 * bi + 1] = (np.cos(th) * ((self.d[on] * fsum[on]).sum() + sigma * lev * f5)
                               - bd['M'] * bd['H'] * ax) / bd['iy']
            acc[3 * bi + 2] = (np.cos(ph) * (self.s[on] * fdiff[on]).sum() + mar[on].sum()
                               + bd['M'] * bd['h'] * (ay * np.cos(ph) + G * np.sin(ph))
                               + sigma * m5) / bd['ix']
        return np.concatenate([vel, acc])

    def wheel_loads(self, t: float, y: np.ndarray) -> np.ndarray:
        """F_n per wheel [axle j left, right, ...] (N): F_c + dF, >= 0."""
        _, _, tire = self.forces(t, y)
        return np.maximum(self.fc[:, None] + tire, 0.0).reshape(-1)
