//! Inline `exp`, `ln`, `exp_m1` and x^a for the hot path: the model's right-hand side (the
//! pressure-ratio powers, the turbine's expansion terms, the exhaust pipe's heat loss) and the
//! closed-form actuator lags of the integrator (docs/integrator.md, "Session 41: libm on the
//! hot path").
//!
//! glibc's functions cost a call through the PLT, its `exp` wrapper (`w_exp_template.c`: the
//! `errno` check around the kernel, about 15 instructions of the 48 per call), and the spill of
//! the caller's live floating-point registers, which are all caller-saved. These are the same
//! textbook algorithms, inline and without the wrapper:
//!
//! - `exp`, `exp_m1`: Tang's table method. x = (k + j/128) ln 2 + r with k, j integers,
//!   0 <= j < 128 and |r| <= ln 2 / 256 (Cody-Waite: ln 2 / 128 in two parts, the first with
//!   36 significant bits, so k' ln 2 / 128 is exact for |k'| < 2^17), then
//!   e^x = 2^k 2^(j/128) (1 + tail_j) e^r, with 2^(j/128) the nearest double, tail_j its
//!   relative error and e^r - 1 by its Taylor polynomial of degree 5 (truncation below
//!   r^6/720 < 6e-19) for `exp`, of degree 6 (below r^7/5040 < 3e-22) for `exp_m1`, which
//!   needs it relative to its result e^x - 1 near |x| = ln 2 / 256. exp_m1 = (2^k 2^(j/128) - 1) + 2^k 2^(j/128) (e^r - 1 + tail_j), where
//!   the first difference is exact for 2^k 2^(j/128) in [1/2, 2^53) (Sterbenz) and its sum
//!   with r is carried with its rounding error, so small arguments keep their relative
//!   accuracy.
//! - `ln`: x = 2^k z with z in [0.687, 1.375) split into 128 subintervals centred on
//!   c_i (c = 1 for the one around 1); ln x = k ln 2 + ln c_i + ln(1 + r) with
//!   r = (z - c_i) / c_i (z - c_i exact by Sterbenz, one rounding in the product with the
//!   rounded 1/c_i), |r| <= 2^-8, and ln(1 + r) by its Taylor polynomial of degree 7
//!   (truncation below r^8/8, i.e. below 2e-18 of the result). ln 2 and ln c_i are kept in two
//!   parts, the first on the grid of 2^-43, so k ln 2 + ln c_i is exact, and the sum with r
//!   is carried with its rounding error (no extra case near 1).
//! - `pow(x, a)` = exp(a ln x) for x > 0 (`powf` otherwise): relative error about
//!   (|a ln x| + 2) eps, for the model's powers with |a ln x| below about 6.
//!
//! No fused multiply-add: the portable x86-64 target has none (docs/integrator.md, session 10).
//!
//! **Accuracy** (tests below, against the standard library, which is within 0.52 units in the
//! last place (ulp) of the exact value): `exp` and `exp_m1` within 1 ulp of std over
//! |x| < 708, `ln` within 1 ulp over every positive normal number. **Special values are std's**:
//! every argument outside the inline path's domain (for `exp`/`exp_m1` zero, |x| >= 708,
//! infinities and NaN; for `ln` zero, negative and subnormal numbers, infinity and NaN) is
//! passed to the standard library, so a NaN of a failed solve propagates as before and
//! overflow, underflow and the signed zeros are std's.

/// 128 / ln 2.
const EXP_N_OVER_LN2: f64 = 184.6649652337873;
/// 1.5 * 2^52: adding it rounds a number below 2^51 in magnitude to an integer, which is then
/// in the low bits of the sum's representation (two's complement).
const EXP_SHIFT: f64 = 6755399441055744.0;
/// ln 2 / 128 rounded to 36 significant bits (the multiple of 2^-43 nearest to it).
const EXP_LN2_N_HI: f64 = 0.005415212348111709;
/// ln 2 / 128 - `EXP_LN2_N_HI`.
const EXP_LN2_N_LO: f64 = 1.2864023111638346e-14;
/// The inline `exp` and `exp_m1` take 0 < |x| < 708 (then 2^k is a normal number; e^708 is
/// 3e307): compared as bit patterns, `|x|.to_bits() - 1 < EXP_LIMIT_BITS - 1`.
const EXP_LIMIT_BITS: u64 = 0x4086_2000_0000_0000; // 708.0
const ABS_MASK: u64 = 0x7fff_ffff_ffff_ffff;

const C3: f64 = 1.0 / 6.0;
const C4: f64 = 1.0 / 24.0;
const C5: f64 = 1.0 / 120.0;
const C6: f64 = 1.0 / 720.0;

/// 2^(j/128), j = 0..127: (the bits of the nearest double T_j, (2^(j/128) - T_j) / T_j
/// rounded), computed with 60 digits (mpmath; the generator is in the test
/// `exp_table_is_two_to_the_j_over_128`'s comment).
static EXP_TABLE: [(u64, f64); 128] = [
    (0x3ff0000000000000, 0.0),
    (0x3ff0163da9fb3335, 9.447885451727066e-17),
    (0x3ff02c9a3e778061, -1.507066976926039e-17),
    (0x3ff04315e86e7f85, -5.679155082825012e-17),
    (0x3ff059b0d3158574, 4.9997448722726326e-17),
    (0x3ff0706b29ddf6de, -4.823683599994895e-17),
    (0x3ff0874518759bc8, 7.357846871247418e-18),
    (0x3ff09e3ecac6f383, 5.773230223741951e-17),
    (0x3ff0b5586cf9890f, 8.189317638195515e-17),
    (0x3ff0cc922b7247f7, 5.326891139980878e-17),
    (0x3ff0e3ec32d3d1a2, 1.6665881442326747e-18),
    (0x3ff0fb66affed31b, -1.128113245461828e-17),
    (0x3ff11301d0125b51, -7.402825309426177e-17),
    (0x3ff12abdc06c31cc, -3.578659767309563e-18),
    (0x3ff1429aaea92de0, -6.170654745608695e-17),
    (0x3ff15a98c8a58e51, 2.919139999949279e-17),
    (0x3ff172b83c7d517b, -2.7939114859515733e-17),
    (0x3ff18af9388c8dea, -5.399285355184285e-17),
    (0x3ff1a35beb6fcb75, 4.776959425256223e-17),
    (0x3ff1bbe084045cd4, -7.927701432338473e-17),
    (0x3ff1d4873168b9aa, 9.341710609905046e-17),
    (0x3ff1ed5022fcd91d, -5.534520675707472e-17),
    (0x3ff2063b88628cd6, 4.585670326662351e-17),
    (0x3ff21f49917ddc96, 2.8582430411116143e-17),
    (0x3ff2387a6e756238, 7.826573258636076e-17),
    (0x3ff251ce4fb2a63f, 4.053626906769216e-17),
    (0x3ff26b4565e27cdd, 2.823784425951061e-17),
    (0x3ff284dfe1f56381, -7.882802262487991e-17),
    (0x3ff29e9df51fdee1, 3.2904726646008416e-17),
    (0x3ff2b87fd0dad990, -1.5792094703347882e-18),
    (0x3ff2d285a6e4030b, 4.721368121170128e-17),
    (0x3ff2ecafa93e2f56, 1.3045277096919659e-17),
    (0x3ff306fe0a31b715, 3.3484623336251524e-17),
    (0x3ff32170fc4cd831, 3.8611199774925664e-17),
    (0x3ff33c08b26416ff, 5.527550048505249e-17),
    (0x3ff356c55f929ff1, -3.927184172445234e-17),
    (0x3ff371a7373aa9cb, -6.346552106729483e-17),
    (0x3ff38cae6d05d866, -8.684417614865944e-17),
    (0x3ff3a7db34e59ff7, -1.5456342819397733e-17),
    (0x3ff3c32dc313a8e5, -8.70763476495455e-17),
    (0x3ff3dea64c123422, 3.750854201303127e-17),
    (0x3ff3fa4504ac801c, -6.616854503526488e-17),
    (0x3ff4160a21f72e2a, -5.346099009198751e-18),
    (0x3ff431f5d950a897, -2.443726321015018e-17),
    (0x3ff44e086061892d, 2.1023049675215714e-18),
    (0x3ff46a41ed1d0057, 7.771067937501065e-17),
    (0x3ff486a2b5c13cd0, 1.3357510088834541e-17),
    (0x3ff4a32af0d7d3de, 6.938291696959204e-17),
    (0x3ff4bfdad5362a27, 1.9572585293112036e-17),
    (0x3ff4dcb299fddd0d, 6.632256961675804e-17),
    (0x3ff4f9b2769d2ca7, -5.478069123926778e-17),
    (0x3ff516daa2cf6642, -4.140839310392624e-17),
    (0x3ff5342b569d4f82, -2.1571477251208752e-17),
    (0x3ff551a4ca5d920f, -3.8287766552120535e-17),
    (0x3ff56f4736b527da, 6.663804589232195e-17),
    (0x3ff58d12d497c7fd, 2.3936187400285282e-17),
    (0x3ff5ab07dd485429, 5.68648095791174e-17),
    (0x3ff5c9268a5946b7, 1.1264523354521684e-18),
    (0x3ff5e76f15ad2148, 7.007875046906994e-17),
    (0x3ff605e1b976dc09, -5.0119214278381254e-17),
    (0x3ff6247eb03a5585, -4.8923067513522756e-17),
    (0x3ff6434634ccc320, -3.5260089953269434e-17),
    (0x3ff6623882552225, -6.872303720902018e-17),
    (0x3ff68155d44ca973, 5.001446664133532e-18),
    (0x3ff6a09e667f3bcd, -6.835808657661922e-17),
    (0x3ff6c012750bdabf, -1.1307344092910212e-17),
    (0x3ff6dfb23c651a2f, -8.416011634717156e-18),
    (0x3ff6ff7df9519484, -2.9247977035436566e-17),
    (0x3ff71f75e8ec5f74, -2.092304381843353e-17),
    (0x3ff73f9a48a58174, -3.9778645875427124e-17),
    (0x3ff75feb564267c9, -3.833464968654295e-17),
    (0x3ff780694fde5d3f, 5.763611164480894e-17),
    (0x3ff7a11473eb0187, -2.3591094770850053e-17),
    (0x3ff7c1ed0130c132, 7.260074661098575e-17),
    (0x3ff7e2f336cf4e62, 9.50689710108796e-18),
    (0x3ff80427543e1a12, -4.272956133839906e-17),
    (0x3ff82589994cce13, -6.735219232374683e-17),
    (0x3ff8471a4623c7ad, -2.8396044410430936e-17),
    (0x3ff868d99b4492ed, -7.226635472101257e-17),
    (0x3ff88ac7d98a6699, 5.786121003395918e-17),
    (0x3ff8ace5422aa0db, 5.1548301170786783e-17),
    (0x3ff8cf3216b5448c, -9.416257568878152e-18),
    (0x3ff8f1ae99157736, 2.4253985766689806e-17),
    (0x3ff9145b0b91ffc6, -6.604314051707707e-17),
    (0x3ff93737b0cdc5e5, -6.432131775424189e-18),
    (0x3ff95a44cbc8520f, -1.2204007601863921e-17),
    (0x3ff97d829fde4e50, -6.336161863401293e-17),
    (0x3ff9a0f170ca07ba, -3.7800879246373815e-17),
    (0x3ff9c49182a3f090, 1.5341410053603723e-17),
    (0x3ff9e86319e32323, 1.2932855580427452e-17),
    (0x3ffa0c667b5de565, -4.123367330661149e-17),
    (0x3ffa309bec4a2d33, 4.703083974463456e-17),
    (0x3ffa5503b23e255d, -6.152602891550265e-17),
    (0x3ffa799e1330b358, 5.827849326195279e-17),
    (0x3ffa9e6b5579fdbf, 3.540948262646183e-17),
    (0x3ffac36bbfd3f37a, -3.2741571320938764e-17),
    (0x3ffae89f995ad3ad, 4.875160526227062e-17),
    (0x3ffb0e07298db666, -5.718569790077838e-17),
    (0x3ffb33a2b84f15fb, -4.719539664590972e-18),
    (0x3ffb59728de5593a, -5.773451958805706e-17),
    (0x3ffb7f76f2fb5e47, -1.0772487078934056e-17),
    (0x3ffba5b030a1064a, -6.221808618533911e-17),
    (0x3ffbcc1e904bc1d2, 1.821405440362259e-17),
    (0x3ffbf2c25bd71e09, -6.155536546227639e-17),
    (0x3ffc199bdd85529c, 1.685487290628973e-17),
    (0x3ffc40ab5fffd07a, 5.3581249177694816e-17),
    (0x3ffc67f12e57d14b, 3.621615935336894e-17),
    (0x3ffc8f6d9406e7b5, 8.588379527574144e-18),
    (0x3ffcb720dcef9069, 1.01562190116415e-17),
    (0x3ffcdf0b555dc3fa, -2.869134889187244e-17),
    (0x3ffd072d4a07897c, -5.495118966122005e-17),
    (0x3ffd2f87080d89f2, -5.56965572431627e-17),
    (0x3ffd5818dcfba487, 1.790126907604513e-17),
    (0x3ffd80e316c98398, -3.2211766346200164e-17),
    (0x3ffda9e603db3285, 5.265370768556274e-17),
    (0x3ffdd321f301b460, 3.5089866402403033e-17),
    (0x3ffdfc97337b9b5f, -3.266924100901318e-17),
    (0x3ffe264614f5a129, -4.3657593008079375e-17),
    (0x3ffe502ee78b3ff6, 1.7963932659833022e-17),
    (0x3ffe7a51fbc74c83, 3.4300925275214166e-17),
    (0x3ffea4afa2a490da, -5.545065618639427e-17),
    (0x3ffecf482d8e67f1, -5.149009745457733e-17),
    (0x3ffefa1bee615a27, 5.336805878514151e-17),
    (0x3fff252b376bba97, 3.498978661192973e-17),
    (0x3fff50765b6e4540, 4.5784915277060095e-17),
    (0x3fff7bfdad9cbe14, -5.241934575393899e-17),
    (0x3fffa7c1819e90d8, 2.0414278897578303e-17),
    (0x3fffd3c22b8f71f1, 4.124842848606488e-18),
];

/// x = (k + j/128) ln 2 + r: returns (2^k T_j, tail_j, r, r_err) with |r| <= 0.0028 and
/// r + r_err the reduced argument to about 2^-100 (r rounded, r_err its rounding error), so
/// that e^x = 2^k T_j (1 + tail_j) e^(r + r_err). For 0 < |x| < 708 only.
#[inline(always)]
fn exp_reduce(x: f64) -> (f64, f64, f64, f64) {
    let kd = x * EXP_N_OVER_LN2 + EXP_SHIFT;
    let ki = kd.to_bits(); // low bits: k' = 128 k + j, two's complement
    let kd = kd - EXP_SHIFT; // k' exactly
    let r_hi = x - kd * EXP_LN2_N_HI; // the product and the difference are exact
    let r_lo = -kd * EXP_LN2_N_LO;
    let r = r_hi + r_lo;
    let r_err = (r_hi - r) + r_lo; // |r_hi| >= |r_lo| (exp_m1 only: dead code in exp)
    let (t_bits, tail) = EXP_TABLE[(ki & 127) as usize];
    // T_j in [1, 2) with k added to its exponent field: (ki >> 7) << 52 keeps floor(k'/128)
    // (the shift constant's own bits move out of the word)
    let scale = f64::from_bits(t_bits.wrapping_add((ki >> 7) << 52));
    (scale, tail, r, r_err)
}

#[inline(always)]
fn exp_inline_domain(x: f64) -> bool {
    (x.to_bits() & ABS_MASK).wrapping_sub(1) < EXP_LIMIT_BITS - 1
}

/// e^x, within 1 ulp of [`f64::exp`]; its special values (module doc).
#[inline(always)]
pub fn exp(x: f64) -> f64 {
    if !exp_inline_domain(x) {
        return std_exp(x);
    }
    let (scale, tail, r, _) = exp_reduce(x);
    // e^r - 1 + tail to 6e-19 (r^6/720, and tail r < 3e-19, left out: relative to e^x both
    // are below 0.006 ulp), summed in the order of the shortest dependency chain from r
    let r2 = r * r;
    let em1 = (r + tail) + (r2 * (0.5 + r * C3) + r2 * r2 * (C4 + r * C5));
    scale + scale * em1
}

/// e^x - 1, within 1 ulp of [`f64::exp_m1`] (accurate for small |x|); its special values
/// (module doc).
#[inline(always)]
pub fn exp_m1(x: f64) -> f64 {
    if !exp_inline_domain(x) {
        return std_exp_m1(x);
    }
    let (scale, tail, r, r_err) = exp_reduce(x);
    // T_j (1 + tail) e^r = T_j (1 + r + q): q = tail (1 + r) + e^r - 1 - r to 3e-22 (degree 6:
    // relative to e^x - 1 near |x| = ln 2 / 256 the r^6/720 of degree 5 would be 1.2 ulp)
    let r2 = r * r;
    let q = tail * (1.0 + r) + r2 * (0.5 + r * C3) + r2 * r2 * (C4 + r * C5 + r2 * C6);
    // (2^k T_j - 1) + 2^k T_j (r + q) = s1 + r + (q + s1 (r + q)): s1 = 2^k T_j - 1 is exact
    // for 2^k T_j in [1/2, 2^53) (Sterbenz) and carried with its rounding error below, s1 + r
    // with its rounding error (|s1| >= 0.0054 >= |r| unless s1 = 0), as is r's own, so where
    // s1 and r cancel (|x| near ln 2 / 256 and its odd multiples) no rounding of theirs is
    // magnified
    let s1 = scale - 1.0;
    let s1_err = (-1.0 - s1) + scale; // 0 unless 2^k T_j < 1/2 (then |-1| > 2^k T_j)
    let hi = s1 + r;
    let lo = (s1 - hi) + r;
    hi + ((lo + (r_err + s1_err)) + (q + s1 * (r + q)))
}

#[cold]
#[inline(never)]
fn std_exp(x: f64) -> f64 {
    x.exp()
}

#[cold]
#[inline(never)]
fn std_exp_m1(x: f64) -> f64 {
    x.exp_m1()
}

#[cold]
#[inline(never)]
fn std_ln(x: f64) -> f64 {
    x.ln()
}

/// The bits of 0.6875 less half a subinterval: z = x / 2^k lies in [`LN_OFF`, `LN_OFF` + 2^52)
/// as bit patterns, and subinterval i = bits 45-51 of z's offset from it, centred on
/// c_i = bits 0x3fe6000000000000 + i 2^45 (c_80 = 1).
const LN_OFF: u64 = 0x3fe6_0000_0000_0000 - (1 << 44);
/// ln 2 rounded to a multiple of 2^-43 (43 significant bits: k ln 2 is exact for |k| < 1024).
const LN2_HI: f64 = 0.6931471805598903;
/// ln 2 - `LN2_HI`.
const LN2_LO: f64 = 5.497923018708371e-14;

const L3: f64 = 1.0 / 3.0;
const L5: f64 = 1.0 / 5.0;
const L6: f64 = -1.0 / 6.0;
const L7: f64 = 1.0 / 7.0;

/// A subinterval of the logarithm's reduction: its centre c, 1/c rounded, and ln c as the
/// multiple of 2^-43 nearest to it plus the rest.
#[derive(Clone, Copy)]
struct LnEntry {
    c: f64,
    invc: f64,
    logc_hi: f64,
    logc_lo: f64,
}

/// ln c_i in two parts (60 digits, mpmath; generator in the test
/// `ln_table_is_the_log_of_the_centres`'s comment).
const LOGC: [(f64, f64); 128] = [
    (-0.3746934494414518, 4.1082176222359656e-14),
    (-0.3690277119056873, -4.6049893053233095e-14),
    (-0.36339389418742485, -5.2479106361060915e-14),
    (-0.35779163863878694, -2.0543970779333266e-14),
    (-0.35222059358932256, -2.953765578672408e-14),
    (-0.3466804132137895, 5.277820018864269e-14),
    (-0.3411707574027787, 1.156568624616423e-14),
    (-0.3356912916381134, -2.8136969901227338e-14),
    (-0.33024168687052224, -5.4612144489920215e-14),
    (-0.3248216194012912, 5.351646604259541e-14),
    (-0.31943077076641657, 5.534326352070679e-14),
    (-0.3140688276249648, -1.1054030169005386e-14),
    (-0.30873548164959175, -2.1522127491642888e-14),
    (-0.3034304294199046, -1.548345993498083e-14),
    (-0.29815337231912054, 4.4204083338755686e-14),
    (-0.29290401643288533, -4.727452940514406e-14),
    (-0.28768207245173016, -5.076326383153408e-14),
    (-0.28248725557466514, -1.1782016386565151e-14),
    (-0.27731928541618345, -5.089628039500759e-14),
    (-0.27217788591576664, -4.903580708156347e-14),
    (-0.2670627852490952, 4.996736502345936e-14),
    (-0.26197371574153294, -4.102651071698446e-14),
    (-0.2569104137850218, -5.465121253624792e-15),
    (-0.25187261975509045, 2.037449094215686e-14),
    (-0.2468600779315011, -2.4688324156011588e-14),
    (-0.24187253642048745, 7.252318953240293e-16),
    (-0.2369097470783572, -5.015686013791602e-16),
    (-0.2319714654378231, 4.7955860343296286e-14),
    (-0.22705745063535687, 1.078736749871691e-14),
    (-0.22216746534115828, 3.979844515951702e-15),
    (-0.21730127569003344, 5.204008743405884e-14),
    (-0.21245865121420593, 1.2527395755711364e-14),
    (-0.20763936477828793, 4.3425422595242564e-14),
    (-0.20284319251470606, -4.541021984976105e-14),
    (-0.19806991376208316, -1.0634128304268335e-14),
    (-0.1933193110035063, 1.0320443688698849e-14),
    (-0.18859116980752333, -2.6693431578015818e-14),
    (-0.18388527877016259, 2.5223102140407338e-14),
    (-0.17920142945774842, 3.742530094732263e-14),
    (-0.17453941635187675, -2.2924522154618074e-14),
    (-0.16989903679541385, 1.6376276414097503e-14),
    (-0.16528009093906348, -3.9440046718453496e-14),
    (-0.16068238169043525, -3.821577743916796e-14),
    (-0.15610571466311285, 5.119408840555065e-14),
    (-0.15154989812720032, -6.157896229122976e-16),
    (-0.14701474296180095, -8.710783796122478e-15),
    (-0.14250006260726877, -1.4256439478199035e-14),
    (-0.13800567301939282, -5.0900642926060466e-14),
    (-0.13353139262449076, -3.1859736349078334e-14),
    (-0.1290770422751848, 4.2451216089619995e-14),
    (-0.12464244520731427, 3.767012502308738e-14),
    (-0.12022742699821265, 5.2849453521890294e-14),
    (-0.11583181552509814, -2.3568822182038756e-14),
    (-0.11145544092528326, -3.957125899799804e-14),
    (-0.10709813555638448, 1.7376727386423858e-14),
    (-0.10275973395778237, 1.3438406228830954e-14),
    (-0.09844007281321865, -3.3871241029241416e-14),
    (-0.09413899091384792, -1.3990307490818967e-14),
    (-0.08985632912185793, -3.1218748807418837e-15),
    (-0.08559193033545398, 5.046674438470119e-14),
    (-0.08134563945395712, 4.713370778300984e-15),
    (-0.07711730334438016, -5.1128335719851986e-14),
    (-0.07290677080811747, 2.9690894981172655e-14),
    (-0.06871389254808946, 3.765296820388875e-14),
    (-0.0645385211375924, 2.1225608044809997e-14),
    (-0.06038051098892083, 1.3352588834854848e-14),
    (-0.056239718322899535, 2.345674491018699e-14),
    (-0.05211600113898385, -3.0171021061886944e-14),
    (-0.048009219186383234, 2.262629393030674e-14),
    (-0.04391923393484376, 8.269399178187412e-15),
    (-0.039845908547249564, 4.9893776716773285e-14),
    (-0.03578910785154221, -4.3066973476878145e-14),
    (-0.03174869831457272, -7.580310369375161e-15),
    (-0.02772454801481672, -3.8141534432648766e-14),
    (-0.023716526617363343, 4.730054772033249e-14),
    (-0.019724505347767263, -1.1326399700142234e-14),
    (-0.01574835696817445, 3.527980389655325e-14),
    (-0.01178795575208369, 4.1449261919523146e-14),
    (-0.007843177461040796, 1.4902732911301337e-14),
    (-0.0039138993211054185, -3.0910598346555043e-14),
    (0.0, 0.0),
    (0.0077821404420319595, 2.298941004620351e-14),
    (0.015504186535963527, 1.7274567499706107e-15),
    (0.023167059281490765, 4.361324067851568e-14),
    (0.03077165866670839, 4.529814257790929e-14),
    (0.038318864302141264, -4.6652946995830086e-15),
    (0.045809536031242715, 5.148849572685811e-14),
    (0.053244514518837605, -2.532168943117445e-14),
    (0.06062462181648698, -5.213620639136504e-14),
    (0.06795066190852594, -1.8195060030168815e-14),
    (0.07522342123763792, -5.0396178134370583e-14),
    (0.08244366921110213, -2.7541708360737882e-14),
    (0.089612158689647, 4.012913552726574e-14),
    (0.09672962645856842, -1.7306161136093256e-14),
    (0.10379679368168127, -3.7700471749674615e-14),
    (0.11081436634026431, 2.5799991283069902e-14),
    (0.11778303565643, -4.654729747598445e-14),
    (0.12470347850091912, 3.811763084710266e-14),
    (0.131576357788731, -1.1729485484531301e-14),
    (0.13840232285906495, 5.4183331379008994e-14),
    (0.1451820098444614, 3.6506824353335045e-14),
    (0.15191604202584585, -3.879296723063646e-15),
    (0.15860503017665906, -2.0472357800461955e-14),
    (0.1652495728952772, 2.99659267292569e-14),
    (0.17185025692663203, 2.7194441649495324e-14),
    (0.1784076574728033, 1.5003333854266542e-14),
    (0.18492233849406148, -4.9485167661250996e-14),
    (0.19139485299967873, -4.9278276214647115e-14),
    (0.19782574332987224, 4.7641388950792196e-14),
    (0.2042155414286526, 3.827767260205414e-14),
    (0.21056476910735, -3.6507188831790577e-16),
    (0.21687393830063684, -2.2477465222466186e-14),
    (0.22314355131425145, -4.169796584527195e-14),
    (0.22937410106487732, -3.149265065191484e-14),
    (0.23556607131274632, 2.0592242769647135e-14),
    (0.2417199368871934, -4.8230289429940886e-14),
    (0.2478361639045943, -1.3029797173308663e-14),
    (0.25391520998095984, 3.600176732637335e-15),
    (0.25995752443691345, 1.2621729398885316e-14),
    (0.2659635484970977, 4.025092402293806e-14),
    (0.2719337154836694, -2.7643769993528702e-14),
    (0.27786845100342816, 2.814323765595281e-14),
    (0.28376817313062475, 1.9852665484979036e-14),
    (0.28963329258306203, -1.9352855826489123e-14),
    (0.2954642128938758, -3.993416384387844e-14),
    (0.3012613305781997, -3.7923164802093147e-14),
    (0.3070250352949415, -2.9655274673691784e-14),
    (0.31275571000389846, -1.5688303180062087e-15),
];

const fn ln_table() -> [LnEntry; 128] {
    let mut t = [LnEntry {
        c: 0.0,
        invc: 0.0,
        logc_hi: 0.0,
        logc_lo: 0.0,
    }; 128];
    let mut i = 0;
    while i < 128 {
        let c = f64::from_bits(0x3fe6_0000_0000_0000 + ((i as u64) << 45));
        t[i] = LnEntry {
            c,
            invc: 1.0 / c,
            logc_hi: LOGC[i].0,
            logc_lo: LOGC[i].1,
        };
        i += 1;
    }
    t
}

static LN_TABLE: [LnEntry; 128] = ln_table();

/// ln x, within 1 ulp of [`f64::ln`]; its special values (module doc).
#[inline(always)]
pub fn ln(x: f64) -> f64 {
    let ix = x.to_bits();
    // positive normal numbers only (zero, subnormals, negatives, infinity, NaN: std)
    const MIN_NORMAL: u64 = 0x0010_0000_0000_0000;
    if ix.wrapping_sub(MIN_NORMAL) >= 0x7ff0_0000_0000_0000 - MIN_NORMAL {
        return std_ln(x);
    }
    let tmp = ix.wrapping_sub(LN_OFF);
    let e = &LN_TABLE[((tmp >> 45) & 127) as usize];
    let k = (tmp as i64) >> 52; // arithmetic shift: floor
    let z = f64::from_bits(ix.wrapping_sub(tmp & (0xfff << 52)));
    let r = (z - e.c) * e.invc;
    let kd = k as f64;
    let w = kd * LN2_HI + e.logc_hi; // exact (both on the grid of 2^-43, |w| < 2^10)
                                     // w + r with its rounding error (|w| >= |r| unless w = 0)
    let hi = w + r;
    let lo = (w - hi) + r;
    // ln(1 + r) - r
    let r2 = r * r;
    let p = r2 * ((-0.5 + r * L3) + r2 * (-0.25 + r * L5) + r2 * r2 * (L6 + r * L7));
    hi + (lo + (e.logc_lo + kd * LN2_LO) + p)
}

/// x^a as exp(a ln x) for x > 0 ([`f64::powf`] otherwise, so every special case of a
/// non-positive or NaN base is `powf`'s). Relative error at most about (|a ln x| + 2) eps.
#[inline(always)]
pub fn pow(x: f64, a: f64) -> f64 {
    if x > 0.0 {
        exp(a * ln(x))
    } else {
        x.powf(a)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Distance in units in the last place between two finite numbers of the same sign (0 for
    /// equal bits; u64::MAX when the signs differ and the numbers are not both zero).
    fn ulps(a: f64, b: f64) -> u64 {
        if a == b {
            return 0;
        }
        if a.is_sign_negative() != b.is_sign_negative() {
            return u64::MAX;
        }
        a.to_bits().abs_diff(b.to_bits())
    }

    /// The largest distance of `f` from `g` over `xs`, with its argument.
    fn max_ulps(
        xs: impl Iterator<Item = f64>,
        f: impl Fn(f64) -> f64,
        g: impl Fn(f64) -> f64,
    ) -> (u64, f64) {
        xs.map(|x| (ulps(f(x), g(x)), x))
            .fold((0, f64::NAN), |m, d| if d.0 > m.0 { d } else { m })
    }

    /// `n` + 1 points evenly spaced over [a, b].
    fn lin(a: f64, b: f64, n: usize) -> impl Iterator<Item = f64> {
        (0..=n).map(move |k| a + (b - a) * k as f64 / n as f64)
    }

    /// `n` + 1 points evenly spaced in the logarithm over [a, b] (a, b > 0).
    fn geo(a: f64, b: f64, n: usize) -> impl Iterator<Item = f64> {
        let (la, lb) = (a.ln(), b.ln());
        (0..=n).map(move |k| (la + (lb - la) * k as f64 / n as f64).exp())
    }

    /// Bit patterns: every `step`-th double from `a` up to `b` (same sign), i.e. dense in every
    /// binade and subinterval whatever the table.
    fn bits(a: f64, b: f64, step: u64) -> impl Iterator<Item = f64> {
        (a.to_bits()..=b.to_bits())
            .step_by(step as usize)
            .map(f64::from_bits)
    }

    // The tables were generated with (Python, mpmath):
    //   mp.dps = 60; T = 2 ** (mpf(j) / 128); hi = float(T); tail = float((T - hi) / hi)
    //   c = the double with bits 0x3fe6000000000000 + (i << 45); L = log(mpf(c))
    //   logc_hi = float(nint(L * 2**43) / 2**43); logc_lo = float(L - logc_hi)
    //   ln 2 / 128 and ln 2 split the same way (2^-43 grid).
    #[test]
    fn exp_table_is_two_to_the_j_over_128() {
        for (j, &(t, tail)) in EXP_TABLE.iter().enumerate() {
            let t = f64::from_bits(t);
            // glibc's pow is correctly rounded here (j/128 is exact)
            assert_eq!(t, 2f64.powf(j as f64 / 128.0), "{j}");
            assert!(tail.abs() <= f64::EPSILON / 2.0, "{j}: {tail}");
        }
        // the split constants: the first parts on the grid of 2^-43, the sums the values
        let grid = 2f64.powi(43);
        for hi in [EXP_LN2_N_HI, LN2_HI] {
            assert_eq!((hi * grid).fract(), 0.0);
        }
        assert_eq!(EXP_LN2_N_HI + EXP_LN2_N_LO, std::f64::consts::LN_2 / 128.0);
        assert_eq!(LN2_HI + LN2_LO, std::f64::consts::LN_2);
        assert_eq!(EXP_N_OVER_LN2, 128.0 / std::f64::consts::LN_2);
        assert_eq!(f64::from_bits(EXP_LIMIT_BITS), 708.0);
    }

    #[test]
    fn ln_table_is_the_log_of_the_centres() {
        let grid = 2f64.powi(43);
        for (i, e) in LN_TABLE.iter().enumerate() {
            assert_eq!(e.invc, 1.0 / e.c);
            assert_eq!((e.logc_hi * grid).fract(), 0.0, "{i}");
            assert!(e.logc_lo.abs() <= 0.5 / grid, "{i}");
            // the two parts round to glibc's (correctly rounded here) ln c
            assert!(ulps(e.logc_hi + e.logc_lo, e.c.ln()) <= 1, "{i}");
            // every centre lies in the middle of its subinterval of bit patterns
            assert_eq!(e.c.to_bits() - LN_OFF, ((i as u64) << 45) + (1 << 44));
        }
        assert_eq!(LN_TABLE[80].c, 1.0);
        assert_eq!(LN_TABLE[80].logc_hi + LN_TABLE[80].logc_lo, 0.0);
    }

    /// Stated tolerance: 1 ulp from std's exp over |x| < 708 (where std, within 0.52 ulp of
    /// the exact value, is the reference).
    #[test]
    fn exp_is_within_one_ulp_of_std() {
        let (m, x) = max_ulps(lin(-708.0, 708.0, 2_000_000), exp, f64::exp);
        assert!(m <= 1, "{m} ulp at {x}");
        // the model's range densely (exhaust pipe, lags, powers)
        let (m, x) = max_ulps(lin(-40.0, 10.0, 2_000_000), exp, f64::exp);
        assert!(m <= 1, "{m} ulp at {x}");
        for s in [1.0, -1.0] {
            let (m, x) = max_ulps(geo(1e-300, 700.0, 1_000_000).map(|x| s * x), exp, f64::exp);
            assert!(m <= 1, "{m} ulp at {x}");
        }
    }

    #[test]
    fn exp_m1_is_within_one_ulp_of_std() {
        let (m, x) = max_ulps(lin(-708.0, 708.0, 2_000_000), exp_m1, f64::exp_m1);
        assert!(m <= 1, "{m} ulp at {x}");
        // the turbine's a ln Pi_t and the compressor's: small arguments, relative accuracy
        let (m, x) = max_ulps(lin(-3.0, 3.0, 2_000_000), exp_m1, f64::exp_m1);
        assert!(m <= 1, "{m} ulp at {x}");
        for s in [1.0, -1.0] {
            let (m, x) = max_ulps(
                geo(1e-300, 700.0, 1_000_000).map(|x| s * x),
                exp_m1,
                f64::exp_m1,
            );
            assert!(m <= 1, "{m} ulp at {x}");
        }
    }

    #[test]
    fn ln_is_within_one_ulp_of_std() {
        // every binade of the normal numbers, and around 1 densely
        let (m, x) = max_ulps(bits(f64::MIN_POSITIVE, f64::MAX, 1 << 42), ln, f64::ln);
        assert!(m <= 1, "{m} ulp at {x}");
        let (m, x) = max_ulps(bits(0.25, 4.0, 1 << 31), ln, f64::ln);
        assert!(m <= 1, "{m} ulp at {x}");
        let (m, x) = max_ulps(bits(0.98, 1.02, 1 << 26), ln, f64::ln);
        assert!(m <= 1, "{m} ulp at {x}");
        let (m, x) = max_ulps(lin(1e-4, 4.0, 2_000_000), ln, f64::ln);
        assert!(m <= 1, "{m} ulp at {x}");
    }

    #[test]
    fn special_values_are_std() {
        fn same(a: f64, b: f64) -> bool {
            a.to_bits() == b.to_bits() || (a.is_nan() && b.is_nan())
        }
        fn close(a: f64, b: f64) -> bool {
            same(a, b) || ulps(a, b) <= 1
        }
        let xs = [
            0.0,
            -0.0,
            f64::INFINITY,
            f64::NEG_INFINITY,
            f64::NAN,
            -f64::NAN,
            708.0,
            -708.0,
            709.78,
            710.0,
            -745.0,
            -746.0,
            -1e-320,
            1e-320,
            f64::MIN_POSITIVE,
            f64::MAX,
            f64::MIN,
            -1.0,
            1.0,
        ];
        // outside the inline domains: std's bits; inside (the finite values of xs that are
        // not special): within the stated 1 ulp
        for x in xs {
            let inside = x != 0.0 && x.abs() < 708.0;
            let ok: fn(f64, f64) -> bool = if inside { close } else { same };
            assert!(ok(exp(x), x.exp()), "exp({x})");
            assert!(ok(exp_m1(x), x.exp_m1()), "exp_m1({x})");
            let ok: fn(f64, f64) -> bool = if x.is_normal() && x > 0.0 {
                close
            } else {
                same
            };
            assert!(ok(ln(x), x.ln()), "ln({x})");
            for a in [0.27, -0.5, 2.0] {
                assert!(same(pow(x, a), x.powf(a)) || x > 0.0, "pow({x}, {a})");
            }
        }
        assert_eq!(ln(1.0).to_bits(), 0.0f64.to_bits());
        assert_eq!(exp_m1(-0.0).to_bits(), (-0.0f64).to_bits());
        assert!(ln(-1.0).is_nan() && ln(f64::NAN).is_nan() && exp(f64::NAN).is_nan());
        assert!(pow(-2.0, 0.27).is_nan() && pow(f64::NAN, 0.27).is_nan());
        assert_eq!(pow(f64::INFINITY, 0.27), f64::INFINITY);
        assert_eq!(pow(0.0, 0.27), 0.0);
    }
}
