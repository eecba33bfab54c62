"""Scale the published parameter set physically to another engine of the family.

Usage: python3 scripts/scale-engine.py SRC.toml DST.toml S N_CYL [U_DELTA_MAX_MG]
(e.g. crates/mvem/data/published.toml engine_32l.toml 2.5 16; docs/tuning.md, session 32).

s: flow scale (displacement, manifold volumes, EGR/VGT areas, compressor/turbine flow at the same
pressure ratios), n_cyl: cylinders. The turbocharger is scaled geometrically: radii x sqrt(s) (flow
at the same tip speed ~ R^2), omega_t / sqrt(s) (same tip speed), inertia x sqrt(s)^5; the
omega_t polynomials of eqs (69)-(70) and c_m2, w_tlin follow omega_t; W_copt x s, Q_c's W_c
entries / s, / s^2. Exhaust pipes: d, l x sqrt(s) (the heat-loss exponent of eq. (25) unchanged).
"""
import re, sys, math
src, dst, s, ncyl = sys.argv[1], sys.argv[2], float(sys.argv[3]), float(sys.argv[4])
udmax = float(sys.argv[5]) if len(sys.argv) > 5 else None
k = math.sqrt(s)
txt = open(src).read()
sec = None
out = []
def num(x):
    return repr(float(x))
def scale_line(sec, key, val):
    def f(x): return float(x)
    if sec == "intake_manifold" and key == "v_im": return num(f(val) * s)
    if sec == "exhaust_manifold" and key == "v_em": return num(f(val) * s)
    if sec == "intercooler" and key == "v_ic": return num(f(val) * s)
    if sec == "intercooler" and key == "k_ic": return num(f(val) / s**2)  # same drop at s x flow (eq. (86))
    if sec == "cylinder" and key == "v_d": return num(f(val) * s)
    if sec == "cylinder" and key == "n_cyl": return num(ncyl)
    if sec == "exhaust_pipe" and key in ("d_pipe", "l_pipe"): return num(f(val) * k)
    if sec == "egr_valve" and key == "a_egrmax": return num(f(val) * s)
    if sec == "turbine" and key == "a_vgtmax": return num(f(val) * s)
    if sec == "turbine" and key == "r_t": return num(f(val) * k)
    if sec == "turbine" and key == "w_tlin": return num(f(val) / k)
    if sec == "turbine" and key == "c_m":
        a = [float(x) for x in val.strip("[]").split(",")]
        return "[%s, %s, %s]" % (num(a[0]), num(a[1] / k), num(a[2]))
    if sec == "compressor" and key == "r_c": return num(f(val) * k)
    if sec == "compressor" and key in ("c_wpsi", "c_wphi"):
        a = [float(x) for x in val.strip("[]").split(",")]
        return "[%s, %s, %s]" % (num(a[0] * k * k), num(a[1] * k), num(a[2]))
    if sec == "compressor" and key == "w_copt": return num(f(val) * s)
    if sec == "compressor" and key == "q_c":
        a = [float(x) for x in re.findall(r"-?[0-9.eE+-]+", val)]
        a1, a3, _, a2 = a
        return "[[%s, %s], [%s, %s]]" % (num(a1 / s**2), num(a3 / s), num(a3 / s), num(a2))
    if sec == "turbo" and key == "j_t": return num(f(val) * k**5)
    if sec == "initial" and key == "omega_t": return num(f(val) / k)
    if sec == "input_saturation" and key == "u_delta" and udmax: return "[1.0, %s]" % num(udmax)
    if sec == "turbine" and key == "c_mlin": return "C_MLIN"
    return None
for line in txt.splitlines():
    m = re.match(r"^\[(\w+)\]", line)
    if m: sec = m.group(1)
    m = re.match(r"^(\w+) = (.*)$", line)
    if m and sec:
        v = scale_line(sec, m.group(1), m.group(2))
        if v is not None:
            line = "%s = %s" % (m.group(1), v)
    out.append(line)
t = "\n".join(out) + "\n"
a = [float(x) for x in re.search(r"^c_m = \[(.*)\]$", t, re.M).group(1).split(",")]
w = float(re.search(r"^w_tlin = (.*)$", t, re.M).group(1))
t = t.replace("C_MLIN", repr(a[0] * (w - a[1]) ** a[2]))  # c_mlin tied to c_m at w_tlin
open(dst, "w").write(t)
