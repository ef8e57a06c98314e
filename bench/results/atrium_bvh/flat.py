"""Lavapipe rays per second of the atrium as exported (49 instances of 6 meshes), flattened into
one mesh, and with triangles larger than 4 or 1 m^2 split in four until they are not.

    .venv/bin/python -m bench.converge --export-only --npz bench/npz --width 128 --scenes atrium
    PYTHONPATH=. .venv/bin/python bench/results/atrium_bvh/flat.py pt bench/npz
"""
import sys, time, copy
import numpy as np
from bench.converge import MAX_DEPTH, method_params
from parallax_core.scene import SceneData, Mesh, Instance
import parallax_core as pc

def flatten(sc):
    P, I, N, U, M = [], [], [], [], []
    off = 0
    for inst in sc.instances:
        m = sc.meshes[inst.mesh]
        T = np.asarray(inst.transform, float)
        p = m.positions @ T[:3, :3].T + T[:3, 3]
        P.append(p); I.append(m.indices + off); off += len(p)
        nm = np.linalg.inv(T[:3, :3]).T
        N.append(m.normals @ nm.T if m.normals is not None else np.zeros((len(m.indices), 3, 3)))
        U.append(m.uvs if m.uvs is not None else np.zeros((len(m.indices), 3, 2)))
        M.append(m.material_indices if m.material_indices is not None else np.zeros(len(m.indices), int))
    mesh = Mesh(np.concatenate(P), np.concatenate(I), np.concatenate(N), np.concatenate(U), np.concatenate(M))
    out = copy.copy(sc); out.meshes = [mesh]; out.instances = [Instance(0)]
    return out

def split(sc, max_area):
    meshes = []
    for m in sc.meshes:
        tri = m.positions[m.indices]          # (T,3,3)
        nrm = m.normals if m.normals is not None else None
        uv = m.uvs; mat = m.material_indices
        out_t, out_n, out_u, out_m = [], [], [], []
        stack = [(tri[i], None if nrm is None else nrm[i], None if uv is None else uv[i], None if mat is None else mat[i]) for i in range(len(tri))]
        while stack:
            t, n, u, k = stack.pop()
            a = 0.5 * np.linalg.norm(np.cross(t[1] - t[0], t[2] - t[0]))
            if a <= max_area:
                out_t.append(t); out_n.append(n); out_u.append(u); out_m.append(k); continue
            mid = lambda x: None if x is None else np.array([(x[0]+x[1])/2, (x[1]+x[2])/2, (x[2]+x[0])/2])
            tm, nm_, um = mid(t), mid(n), mid(u)
            for sel in ([0, 3, 5], [3, 1, 4], [5, 4, 2], [3, 4, 5]):
                pick = lambda x, xm: None if x is None else np.concatenate([x, xm])[sel]
                stack.append((pick(t, tm), pick(n, nm_), pick(u, um), k))
        T = np.array(out_t)
        meshes.append(Mesh(T.reshape(-1, 3), np.arange(len(T) * 3).reshape(-1, 3),
                           None if nrm is None else np.array(out_n), None if uv is None else np.array(out_u),
                           None if mat is None else np.array(out_m)))
    out = copy.copy(sc); out.meshes = meshes
    return out

base = SceneData.load(f"{sys.argv[2] if len(sys.argv) > 2 else 'bench/npz'}/atrium.npz")
variants = {"instanced": base, "flat": flatten(base), "flat_split4": split(flatten(base), 4.0),
            "flat_split1": split(flatten(base), 1.0), "inst_split1": split(base, 1.0)}
method = sys.argv[1] if len(sys.argv) > 1 else "pt"
for rep in range(2):
  for name, sc in variants.items():
    s = pc.Session(base.width, base.height, "cpu")
    s.set_params(samples_per_frame=8, max_depth=MAX_DEPTH, depth_leeway=0, seed=0, **method_params(method))
    s.update(sc); s.render(1)
    r0 = s.stats()["rays"]; t = time.perf_counter(); s.render(4); dt = time.perf_counter() - t
    img = s.read("combined")
    tris = sum(len(m.indices) for m in sc.meshes)
    print(f"{name:12s} tris {tris:6d}: {32/dt:5.1f} spp/s {(s.stats()['rays']-r0)/dt/1e6:.2f} Mrays/s mean {img[...,:3].mean():.4f}", flush=True)
