/*
 * The rolling ball, example 2 (gni-trapezoid, Cayley retraction), one GNI step hand-written in C.
 *
 * A line-by-line port of benchmarks/numba_gni.py's current kernel for this case (`_ball_step` with
 * chaplygin = False and the solver EX2_SOLVER = "predicted-newton"): the same formulas, the same
 * operations in the same order, so that with IEEE arithmetic (no -ffast-math, no FMA contraction:
 * -fno-fast-math -ffp-contract=off) it computes the same numbers as the Numba kernel, bit for bit.
 * Read numba_gni.py's module docstring for the derivation; in short:
 *
 *   state (16 doubles): x, y, R (3x3 row-major), p+ (5);
 *   reflection (Comb): lambda_i is one quotient each (mu is constant: C is diagonal);
 *   unknown xi = sigma/h, F(xi) = I xi + (h/2) xi x I xi + (h^2/4) xi (xi . I xi) - p-_omega;
 *   first guess xi_bar = p_bar_omega / I, two fixed-point sweeps, then Newton (Jacobian in closed
 *   form, fused with F; Cramer's rule) until max|delta| <= 1e-8 max(1, max|xi|);
 *   R_{k+1} = cay(h xi) R_k applied without forming cay; p+_{k+1} = p- - h xi x I xi.
 *
 * Built by benchmarks/c_gni.py at benchmark time (cc -O3 [-march=native] -fno-fast-math
 * -ffp-contract=off -shared -fPIC) into a private temporary directory and loaded with ctypes.
 * Only for the benchmark (issue 35): gnipy never uses it.
 */
#include <math.h>
#include <time.h>

/* numba_gni.EX2_PARAMS: (m, r, I1, I2, I3, Omega) */
static const double M_ = 3.0, R_ = 1.0, I1 = 1.0, I2 = 1.1, I3 = 1.2, W_ = 0.2;
#define NEWTON_TOL 1e-8 /* numba_gni.NEWTON_TOL */
#define NEWTON_MAXITER 20 /* numba_gni.NEWTON_MAXITER */
#define SWEEPS 2 /* numba_gni.PREDICTOR_SWEEPS[0] */

static inline double max3(double a, double b, double c)
{
    double m = a > b ? a : b;
    return m > c ? m : c;
}

/* One step: s (16) -> out (16, may alias s); returns the number of Newton iterations. NaN state
 * when Newton fails (as numba_gni: a failure is never silent). */
static int ex2_step(const double *s, double h, double *out)
{
    const double x = s[0], y = s[1];
    const double p0 = s[11], p1 = s[12], p2 = s[13], p3 = s[14], p4 = s[15];
    const double mW = M_ * W_, mr = M_ * R_;
    /* reflection: C = diag(1/m + r^2/I2, 1/m + r^2/I1) */
    const double l0 = (I2 * (p0 + mW * y) - mr * p3) / (I2 + mr * R_);
    const double l1 = (I1 * (p1 - mW * x) + mr * p2) / (I1 + mr * R_);
    const double q2 = R_ * l1, q3 = -R_ * l0, q4 = 0.0;
    const double pm0 = p0 - 2.0 * l0, pm1 = p1 - 2.0 * l1;
    const double pm2 = p2 - 2.0 * q2, pm3 = p3 - 2.0 * q3, pm4 = p4 - 2.0 * q4;
    const double pb2 = p2 - q2, pb3 = p3 - q3, pb4 = p4 - q4;

    /* _ball_solve */
    const double c2 = 0.25 * h * h;
    const double c1 = 0.5 * h;
    const double a = c1 * (I3 - I2), b = c1 * (I1 - I3), c = c1 * (I2 - I1);
    const double r1 = 1.0 / I1, r2 = 1.0 / I2, r3 = 1.0 / I3;
    double k0 = pb2 * r1, k1 = pb3 * r2, k2 = pb4 * r3;
    for (int sw = 0; sw < SWEEPS; ++sw) {
        const double M0 = I1 * k0, M1 = I2 * k1, M2 = I3 * k2;
        const double sM = k0 * M0 + k1 * M1 + k2 * M2;
        const double n0 = (pm2 - a * (k1 * k2) - (c2 * k0) * sM) * r1;
        const double n1 = (pm3 - b * (k0 * k2) - (c2 * k1) * sM) * r2;
        const double n2 = (pm4 - c * (k0 * k1) - (c2 * k2) * sM) * r3;
        k0 = n0;
        k1 = n1;
        k2 = n2;
    }
    int its = NEWTON_MAXITER, ok = 0;
    for (int it = 1; it <= NEWTON_MAXITER; ++it) {
        /* _ball_fj: F and J fused */
        const double M0 = I1 * k0, M1 = I2 * k1, M2 = I3 * k2;
        const double sM = k0 * M0 + k1 * M1 + k2 * M2;
        const double u0 = c2 * k0, u1 = c2 * k1, u2 = c2 * k2;
        const double q = c2 * sM;
        const double t0 = 2.0 * u0, t1 = 2.0 * u1, t2 = 2.0 * u2;
        const double F0 = (M0 - pm2) + a * (k1 * k2) + u0 * sM;
        const double F1 = (M1 - pm3) + b * (k0 * k2) + u1 * sM;
        const double F2 = (M2 - pm4) + c * (k0 * k1) + u2 * sM;
        const double J00 = (I1 + t0 * M0) + q, J01 = a * k2 + t0 * M1, J02 = a * k1 + t0 * M2;
        const double J10 = b * k2 + t1 * M0, J11 = (I2 + t1 * M1) + q, J12 = b * k0 + t1 * M2;
        const double J20 = c * k1 + t2 * M0, J21 = c * k0 + t2 * M1, J22 = (I3 + t2 * M2) + q;
        /* _newton_update3: Cramer's rule */
        const double C00 = J11 * J22 - J12 * J21;
        const double C01 = J12 * J20 - J10 * J22;
        const double C02 = J10 * J21 - J11 * J20;
        const double C10 = J02 * J21 - J01 * J22;
        const double C11 = J00 * J22 - J02 * J20;
        const double C12 = J01 * J20 - J00 * J21;
        const double C20 = J01 * J12 - J02 * J11;
        const double C21 = J02 * J10 - J00 * J12;
        const double C22 = J00 * J11 - J01 * J10;
        const double nid = -1.0 / (J00 * C00 + J01 * C01 + J02 * C02);
        const double d0 = (C00 * F0 + C10 * F1 + C20 * F2) * nid;
        const double d1 = (C01 * F0 + C11 * F1 + C21 * F2) * nid;
        const double d2 = (C02 * F0 + C12 * F1 + C22 * F2) * nid;
        k0 += d0;
        k1 += d1;
        k2 += d2;
        if (max3(fabs(d0), fabs(d1), fabs(d2)) <= NEWTON_TOL * max3(1.0, fabs(k0), max3(fabs(k1), fabs(k2), 0.0))) {
            its = it;
            ok = 1;
            break;
        }
    }
    if (!ok) {
        for (int i = 0; i < 16; ++i)
            out[i] = NAN;
        return NEWTON_MAXITER;
    }
    /* R_{k+1} = cay(sigma) R_k: column j += alpha (B + sigma x B / 2), B = sigma x R_{:j} */
    const double s0 = h * k0, s1 = h * k1, s2 = h * k2;
    const double al = 4.0 / (4.0 + (s0 * s0 + s1 * s1 + s2 * s2));
    const double z0 = 0.5 * s0, z1 = 0.5 * s1, z2 = 0.5 * s2;
    const double R00 = s[2], R01 = s[3], R02 = s[4], R10 = s[5], R11 = s[6], R12 = s[7];
    const double R20 = s[8], R21 = s[9], R22 = s[10];
    const double A0 = s1 * R20 - s2 * R10, A1 = s2 * R00 - s0 * R20, A2 = s0 * R10 - s1 * R00;
    const double B0 = s1 * R21 - s2 * R11, B1 = s2 * R01 - s0 * R21, B2 = s0 * R11 - s1 * R01;
    const double E0 = s1 * R22 - s2 * R12, E1 = s2 * R02 - s0 * R22, E2 = s0 * R12 - s1 * R02;
    const double hd0 = h * (I3 - I2), hd1 = h * (I1 - I3), hd2 = h * (I2 - I1);
    out[0] = x + h * pm0 / M_;
    out[1] = y + h * pm1 / M_;
    out[2] = R00 + al * (A0 + (z1 * A2 - z2 * A1));
    out[5] = R10 + al * (A1 + (z2 * A0 - z0 * A2));
    out[8] = R20 + al * (A2 + (z0 * A1 - z1 * A0));
    out[3] = R01 + al * (B0 + (z1 * B2 - z2 * B1));
    out[6] = R11 + al * (B1 + (z2 * B0 - z0 * B2));
    out[9] = R21 + al * (B2 + (z0 * B1 - z1 * B0));
    out[4] = R02 + al * (E0 + (z1 * E2 - z2 * E1));
    out[7] = R12 + al * (E1 + (z2 * E0 - z0 * E2));
    out[10] = R22 + al * (E2 + (z0 * E1 - z1 * E0));
    out[11] = pm0;
    out[12] = pm1;
    out[13] = pm2 - hd0 * (k1 * k2);
    out[14] = pm3 - hd1 * (k0 * k2);
    out[15] = pm4 - hd2 * (k0 * k1);
    return its;
}

/* `steps` steps from state0 (16) into out (16); returns the total number of Newton iterations.
 * The state lives in a local array (registers after optimization): no allocation. */
long gni_ex2_run(const double *state0, double h, long steps, double *out)
{
    double s[16];
    long n = 0;
    for (int i = 0; i < 16; ++i)
        s[i] = state0[i];
    for (long k = 0; k < steps; ++k)
        n += ex2_step(s, h, s);
    for (int i = 0; i < 16; ++i)
        out[i] = s[i];
    return n;
}

/* The minimum over `repeats` runs of gni_ex2_run's wall time in seconds (CLOCK_MONOTONIC), timed
 * here so that the ctypes call's overhead is not counted; the last run's state goes to out. */
double gni_ex2_time(const double *state0, double h, long steps, long repeats, double *out)
{
    double best = INFINITY;
    for (long r = 0; r < repeats; ++r) {
        struct timespec t0, t1;
        clock_gettime(CLOCK_MONOTONIC, &t0);
        gni_ex2_run(state0, h, steps, out);
        clock_gettime(CLOCK_MONOTONIC, &t1);
        const double dt = (double)(t1.tv_sec - t0.tv_sec) + 1e-9 * (double)(t1.tv_nsec - t0.tv_nsec);
        if (dt < best)
            best = dt;
    }
    return best;
}
