"""Generate shaders/shared/ggx_tables.h: directional albedos of our single-scatter GGX lobes
for multiscatter energy compensation (Kulla & Conty 2017; Turquin 2019), parametrised as
Cycles' tables are (so Multiscatter GGX renders as Cycles does):

    GGX_E[r][mu]          32 x 32   reflection, F = 1        r = Blender roughness, mu = wo.z
    GGX_EAVG[r]           32        2 int_0^1 E(mu) mu dmu
    GLASS_E[r][mu][z]     32^3      glass (F-weighted reflection + refraction), eta = ior
    GLASS_INV_E[r][mu][z] 32^3      the same leaving the glass, eta = 1 / ior
    SPEC_S[r][mu][z]      16^3      Principled specular/coat layer: the E-normalised mean of
                                    s = (F(wo.m) - F0) / (1 - F0) over the reflection lobe, so its
                                    albedo is mix(F0 tint, 1, s) (Cycles' ggx_gen_schlick_ior_s)
    SHEEN_E[r][mu]        32 x 32   albedo / 2 (clipped to 1) of the Principled sheen lobe
                                    (principled.glsl's Charlie sheen), r = Sheen Roughness

with z = sqrt((ior - 1) / (ior + 1)) and grid points i / (n - 1) on every axis (lookups
interpolate linearly between them). The host uploads the words once per session into a
storage buffer (BINDING_GGX_TABLES); shaders see only the offsets. Each value is
E = E_m[weight] over visible normals m
(Heitz 2018) with the sampler of shaders/lib/bsdf.glsl: weight G2/G1 for a valid direction,
the glass choosing reflection with probability F; stratified m, 64^2 per entry. Stored as
unorm16 pairs in uints (E is in (0, 1]).

    .venv/bin/python scripts/ggx_albedo_tables.py     # rewrites shaders/shared/ggx_tables.h
    .venv/bin/python scripts/ggx_albedo_tables.py --keep GGX_E,GGX_EAVG,GLASS_E,GLASS_INV_E
        # the same, but takes the named tables' values from the current header (the glass
        # tables take ~20 minutes; the values are deterministic, so this gives the same file)
"""
import os
import sys

import numpy as np

HERE = os.path.dirname(os.path.abspath(__file__))
OUT = os.path.join(os.path.dirname(HERE), "shaders", "shared", "ggx_tables.h")
STRATA = 64
MU_MIN = 1e-3  # mu = 0 itself is degenerate: use a grazing direction instead


def lambda_ggx(z, alpha):
    z2 = np.minimum(z * z, 1.0)
    tan2 = np.maximum(0.0, 1.0 - z2) / np.maximum(z2, 1e-12)
    return 0.5 * (-1.0 + np.sqrt(1.0 + alpha * alpha * tan2))


def vndf(wo, alpha, u1, u2):
    """Visible normals for wo (3,) and arrays of uniforms (Heitz 2018)."""
    vh = np.array([alpha * wo[0], alpha * wo[1], wo[2]])
    vh /= np.linalg.norm(vh)
    lensq = vh[0] ** 2 + vh[1] ** 2
    t1 = np.array([-vh[1], vh[0], 0.0]) / np.sqrt(lensq) if lensq > 0 else np.array([1.0, 0.0, 0.0])
    t2 = np.cross(vh, t1)
    r, phi = np.sqrt(u1), 2.0 * np.pi * u2
    p1, p2 = r * np.cos(phi), r * np.sin(phi)
    s = 0.5 * (1.0 + vh[2])
    p2 = (1.0 - s) * np.sqrt(np.maximum(0.0, 1.0 - p1 * p1)) + s * p2
    p3 = np.sqrt(np.maximum(0.0, 1.0 - p1 * p1 - p2 * p2))
    nh = p1[:, None] * t1 + p2[:, None] * t2 + p3[:, None] * vh
    m = np.stack([alpha * nh[:, 0], alpha * nh[:, 1], np.maximum(1e-6, nh[:, 2])], axis=1)
    return m / np.linalg.norm(m, axis=1, keepdims=True)


def fresnel(cos_i, eta):
    c = np.abs(cos_i)
    g2 = eta * eta - 1.0 + c * c
    g = np.sqrt(np.maximum(g2, 0.0))
    a = (g - c) / (g + c)
    b = (c * (g + c) - 1.0) / (c * (g - c) + 1.0)
    return np.where(g2 <= 0.0, 1.0, 0.5 * a * a * (1.0 + b * b))


def uniforms():
    i = (np.arange(STRATA) + 0.5) / STRATA
    u1, u2 = np.meshgrid(i, i, indexing="ij")
    return u1.ravel(), u2.ravel()


U1, U2 = uniforms()


def albedo(rough, mu, eta=None):
    """E(mu) of the reflection lobe (eta None, F = 1) or of the glass with relative IOR eta."""
    if rough <= 0.0:
        return 1.0
    alpha = rough * rough
    mu = max(mu, MU_MIN)
    wo = np.array([np.sqrt(1.0 - mu * mu), 0.0, mu])
    m = vndf(wo, alpha, U1, U2)
    wo_m = m @ wo
    g1 = 1.0 / (1.0 + lambda_ggx(mu, alpha))
    wr = 2.0 * wo_m[:, None] * m - wo
    w_refl = np.where(wr[:, 2] > 0, 1.0 / (1.0 + lambda_ggx(mu, alpha) + lambda_ggx(wr[:, 2], alpha)) / g1, 0.0)
    if eta is None:
        return float(w_refl.mean())
    f = fresnel(wo_m, eta)
    # refract(-wo, m, 1/eta)
    e = 1.0 / eta
    k = 1.0 - e * e * (1.0 - wo_m * wo_m)
    wt = -e * wo + (e * wo_m - np.sqrt(np.maximum(k, 0.0)))[:, None] * m
    ok_t = (k > 0) & (wt[:, 2] < 0)
    w_tran = np.where(ok_t, 1.0 / (1.0 + lambda_ggx(mu, alpha) + lambda_ggx(-wt[:, 2], alpha)) / g1, 0.0)
    return float((f * w_refl + (1.0 - f) * w_tran).mean())


def spec_s(rough, mu, eta):
    """Mean of s(F(wo.m)) over the GGX reflection lobe at mu, weighted as its albedo."""
    f0 = ((eta - 1.0) / (eta + 1.0)) ** 2
    mu = max(mu, MU_MIN)
    if rough <= 0.0:
        return float(np.clip((fresnel(mu, eta) - f0) / (1.0 - f0), 0.0, 1.0))
    alpha = rough * rough
    wo = np.array([np.sqrt(1.0 - mu * mu), 0.0, mu])
    m = vndf(wo, alpha, U1, U2)
    wo_m = m @ wo
    wr = 2.0 * wo_m[:, None] * m - wo
    w = np.where(wr[:, 2] > 0, 1.0 / (1.0 + lambda_ggx(mu, alpha) + lambda_ggx(wr[:, 2], alpha)), 0.0)
    s = np.clip((fresnel(wo_m, eta) - f0) / (1.0 - f0), 0.0, 1.0)
    return float((w * s).sum() / max(w.sum(), 1e-12))


SHEEN_MIN_ALPHA = 0.01  # principled.glsl: sheen alpha = max(r^2, this)


def sheen_albedo(rough, mu):
    """E(mu) of the Charlie sheen D(m) V(wo, wi) cos (Estevez & Kulla 2017; visibility of
    Neubelt & Pettineo 2013), by stratified cosine-weighted wi."""
    alpha = max(rough * rough, SHEEN_MIN_ALPHA)
    mu = max(mu, MU_MIN)
    wo = np.array([np.sqrt(1.0 - mu * mu), 0.0, mu])
    r, phi = np.sqrt(U1), 2.0 * np.pi * U2
    wi = np.stack([r * np.cos(phi), r * np.sin(phi), np.sqrt(np.maximum(0.0, 1.0 - U1))], axis=1)
    h = wi + wo
    h /= np.linalg.norm(h, axis=1, keepdims=True)
    sin2 = np.maximum(0.0, 1.0 - h[:, 2] ** 2)
    d = (2.0 + 1.0 / alpha) * sin2 ** (0.5 / alpha) / (2.0 * np.pi)
    v = 1.0 / (4.0 * (wi[:, 2] + mu - wi[:, 2] * mu))
    return float(np.pi * np.mean(d * v))  # f cos / (cos / pi)


def ior_of_z(z):
    z2 = min(z * z, 1.0 - 1e-6)
    return (1.0 + z2) / (1.0 - z2)


def tables(keep=()):
    old = read_header() if keep else {}
    n = 32
    grid = np.linspace(0.0, 1.0, n)
    if "GGX_E" in keep:
        ggx_e = old["GGX_E"][:n * n].reshape(n, n)
    else:
        ggx_e = np.array([[albedo(r, mu) for mu in grid] for r in grid])
    mids = (np.arange(64) + 0.5) / 64
    if "GGX_EAVG" in keep:
        ggx_eavg = old["GGX_EAVG"][:n]
    else:
        ggx_eavg = np.array([2.0 * np.mean([albedo(r, mu) * mu for mu in mids]) for r in grid])
    n = 32  # 16^3 (as Cycles) left the glass furnace up to 4% low near grazing
    grid = np.linspace(0.0, 1.0, n)
    glass = np.zeros((n, n, n))
    glass_inv = np.zeros((n, n, n))
    if "GLASS_E" in keep and "GLASS_INV_E" in keep:
        glass = old["GLASS_E"][:n ** 3].reshape(n, n, n)
        glass_inv = old["GLASS_INV_E"][:n ** 3].reshape(n, n, n)
        grid = []
    for i, r in enumerate(grid):
        print(f"glass roughness {r:.3f}", file=sys.stderr, flush=True)
        for j, mu in enumerate(grid):
            for k, z in enumerate(grid):
                ior = ior_of_z(z)
                glass[i, j, k] = albedo(r, mu, ior)
                glass_inv[i, j, k] = albedo(r, mu, 1.0 / ior)
    n = 16
    grid = np.linspace(0.0, 1.0, n)
    spec = np.array([[[spec_s(r, mu, ior_of_z(z)) for z in grid] for mu in grid] for r in grid])
    grid = np.linspace(0.0, 1.0, 32)
    sheen = np.array([[min(sheen_albedo(r, mu), 2.0) / 2.0 for mu in grid] for r in grid])
    return ggx_e, ggx_eavg, glass, glass_inv, spec, sheen


def read_header():
    """{table name: float values from its offset to the end} of the current header."""
    import re
    text = open(OUT).read()
    offsets = {m.group(1): int(m.group(2)) for m in re.finditer(r"PX_CONST uint (\w+)_OFFSET = (\d+)u;", text)}
    body = text[text.index("GGX_TABLE_WORDS[GGX_TABLE_WORD_COUNT] = {"):]
    words = np.array([int(w, 16) for w in re.findall(r"0x([0-9a-f]{8})u", body)], np.uint32)
    values = np.stack([words & 0xffff, words >> 16], axis=1).ravel() / 65535.0
    return {name: values[o:] for name, o in offsets.items()}


def pack(values):
    q = np.clip(np.rint(np.asarray(values).ravel() * 65535.0), 1, 65535).astype(np.uint32)
    if len(q) % 2:
        q = np.append(q, 0)
    return q[0::2] | (q[1::2] << 16)


def main():
    keep = ()
    if len(sys.argv) > 2 and sys.argv[1] == "--keep":
        keep = tuple(sys.argv[2].split(","))
    ggx_e, ggx_eavg, glass, glass_inv, spec, sheen = tables(keep)
    parts = [("GGX_E", ggx_e), ("GGX_EAVG", ggx_eavg), ("GLASS_E", glass), ("GLASS_INV_E", glass_inv),
             ("SPEC_S", spec), ("SHEEN_E", sheen)]
    lines = ["// Generated by scripts/ggx_albedo_tables.py: do not edit. Directional albedos of the",
             "// single-scatter GGX lobes (see the script), unorm16 pairs; offsets in values.",
             "// Polyglot (C++/GLSL): the shaders read the words from BINDING_GGX_TABLES, which the",
             "// host fills from GGX_TABLE_WORDS (a const array in GLSL makes pipelines slow to build).",
             "// Include after types.h.",
             "#ifndef PARALLAX_GGX_TABLES_H", "#define PARALLAX_GGX_TABLES_H", "",
             "#ifdef __cplusplus", "namespace px {", "#endif"]
    data, offset = [], 0
    for name, table in parts:
        lines.append(f"PX_CONST uint {name}_OFFSET = {offset}u;")
        offset += table.size
        data.append(np.asarray(table).ravel())
    packed = pack(np.concatenate(data))
    lines.append(f"PX_CONST uint GGX_TABLE_WORD_COUNT = {len(packed)}u;")
    lines += ["", "#ifdef __cplusplus", "PX_CONST uint GGX_TABLE_WORDS[GGX_TABLE_WORD_COUNT] = {"]
    words = [f"0x{w:08x}u" for w in packed]
    for i in range(0, len(words), 8):
        lines.append("    " + ", ".join(words[i:i + 8]) + ("," if i + 8 < len(words) else ""))
    lines += ["};", "}  // namespace px", "#endif", "#endif"]
    with open(OUT, "w") as f:
        f.write("\n".join(lines) + "\n")
    print(f"{OUT}: {len(packed)} words; E(r=0.7, mu=0.5) = {ggx_e[round(0.7 * 31), 16]:.4f}")


if __name__ == "__main__":
    main()
