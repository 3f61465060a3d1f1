/* Levenberg-Marquardt on a small pose graph, every iteration in compiled code.
 *
 * The iterations of manopt_lie.optim.LevenbergMarquardt (damping lambda*s*I, a dense Cholesky
 * solve checked as CholeskySolver checks it, the gain ratio, the damping update, the stopping
 * rule and the collapse test of Run), for one between factor on SE(2) or SE(3) whose kernels are
 * the library's native ones, passed in as function pointers (manopt_lie/_native.py's batch
 * drivers). The caller (manopt_lie/optim/_small_lm.py) checks that a problem qualifies, lays
 * out this struct and turns the history into a result; this file holds no policy of its own.
 *
 * H = sum_e A_e^T A_e and g = sum_e A_e^T r_e are dense (column-major, n <= 128 unknowns), the
 * columns of fixed poses zero in A_e and 1 on their diagonal, as LeastSquaresProblem builds them.
 */
#include <math.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

typedef int (*batch_fn)(long long m, const double** arg, const long long* arg_stride, double** res,
                        const long long* res_stride);

enum { GRADIENT_NORM = 1, COST_DECREASE = 2, STEP_SIZE = 3, MAX_ITERATIONS = 4, LINEAR_SOLVER_FAILED = 7,
       NO_PROGRESS = 9, FALLBACK = -1, NO_MEMORY = -2, KERNEL_FAILED = -3 };
enum { COLUMNS = 6 }; /* history: f, |grad|, step, time, damping, rho */

typedef struct {
  /* the graph */
  long long n, m, s2, k;          /* poses, edges, entries of a pose's matrix (9, 16), its tangent dim (3, 6) */
  const long long* edges;          /* (m, 2) */
  const unsigned char* fixed;      /* (n,) */
  const double* z;                 /* (m, s2): the inverse measurements, rows of their matrices */
  const double* sqrt_info;         /* (k*k) shared, (m, k*k) per edge, or NULL (unit noise) */
  long long sqrt_info_stride;      /* 0 (shared) or k*k */
  batch_fn between, log, rplus;    /* (xi, xj, z[, L]) -> (r, [J_i | J_j]); -> r; (x, tau) -> x Exp(tau) */
  /* the settings */
  double lam0, lam_max, kappa, rtol;
  double grad_rtol, grad_atol, min_step, rel_decrease, typical_dist, roundoff, huge;
  long long max_iterations;
  /* in: x0; out: the last point */
  double* x;                       /* (n, s2) */
  /* out */
  double* history;                 /* (max_iterations + 1, COLUMNS) */
  long long records, nfev, ngev, rejected, moved;
  int status;
} lm_problem;

typedef struct { /* one point's evaluation: residuals, Jacobians, cost */
  double *r, *J, cost;
  int jac;
} evaluation;

static double now(void) {
  struct timespec t;
  clock_gettime(CLOCK_MONOTONIC, &t);
  return (double)t.tv_sec + 1e-9 * (double)t.tv_nsec;
}

/* The residuals (and with jac their Jacobians) of every edge at the poses x; 0, or nonzero if a
 * kernel failed. The cost is 1/2 |r|^2 (not finite when a residual is not). */
static int evaluate(const lm_problem* p, const double* x, double* xi, double* xj, evaluation* out) {
  const long long m = p->m, s2 = p->s2, k = p->k;
  for (long long e = 0; e < m; ++e) {
    memcpy(xi + e * s2, x + p->edges[2 * e] * s2, s2 * sizeof(double));
    memcpy(xj + e * s2, x + p->edges[2 * e + 1] * s2, s2 * sizeof(double));
  }
  const double* args[4] = {xi, xj, p->z, p->sqrt_info};
  const long long arg_strides[4] = {s2, s2, s2, p->sqrt_info_stride};
  double* res[2] = {out->r, out->J};
  const long long res_strides[2] = {k, 2 * k * k};
  if ((out->jac ? p->between : p->log)(m, args, arg_strides, res, res_strides)) return 1;
  double sum = 0.0;
  for (long long i = 0; i < m * k; ++i) sum += out->r[i] * out->r[i];
  out->cost = 0.5 * sum;
  if (out->jac) { /* the fixed poses' columns: zero, so their update is exactly zero */
    for (long long e = 0; e < m; ++e)
      for (int s = 0; s < 2; ++s)
        if (p->fixed[p->edges[2 * e + s]])
          for (long long row = 0; row < k; ++row) memset(out->J + e * 2 * k * k + row * 2 * k + s * k, 0, k * sizeof(double));
  }
  return 0;
}

/* H = sum_e A_e^T A_e (+1 on the fixed poses' diagonal) and g = sum_e A_e^T r_e, with A_e = [J_i | J_j];
 * whether they (and the Jacobians' cost) are finite. */
static int assemble(const lm_problem* p, const evaluation* ev, double* H, double* g) {
  const long long k = p->k, w = 2 * k, N = p->n * k;
  memset(H, 0, N * N * sizeof(double));
  memset(g, 0, N * sizeof(double));
  long long col[12];
  for (long long e = 0; e < p->m; ++e) {
    const double* A = ev->J + e * k * w;
    const double* r = ev->r + e * k;
    for (long long a = 0; a < w; ++a) col[a] = p->edges[2 * e + a / k] * k + a % k;
    for (long long a = 0; a < w; ++a) {
      double ga = 0.0;
      for (long long row = 0; row < k; ++row) ga += A[row * w + a] * r[row];
      g[col[a]] += ga;
      for (long long b = 0; b < w; ++b) {
        double h = 0.0;
        for (long long row = 0; row < k; ++row) h += A[row * w + a] * A[row * w + b];
        H[col[b] * N + col[a]] += h;
      }
    }
  }
  for (long long v = 0; v < p->n; ++v)
    if (p->fixed[v])
      for (long long c = v * k; c < (v + 1) * k; ++c) H[c * N + c] += 1.0;
  int finite = isfinite(ev->cost);
  for (long long i = 0; i < N && finite; ++i) finite = isfinite(g[i]);
  for (long long i = 0; i < N * N && finite; ++i) finite = isfinite(H[i]);
  return finite;
}

/* sqrt(sum v_i^2), rescaled by max |v_i| when the sum leaves [1e-250, 1e250] (Run.norm). */
static double safe_norm(const double* v, long long n) {
  double sum = 0.0;
  for (long long i = 0; i < n; ++i) sum += v[i] * v[i];
  if (sum >= 1e-250 && sum <= 1e250) return sqrt(sum);
  double a = 0.0;
  for (long long i = 0; i < n; ++i) a = fmax(a, fabs(v[i]));
  if (a == 0.0 || !isfinite(a)) return a == 0.0 ? 0.0 : (isnan(sum) ? NAN : INFINITY);
  sum = 0.0;
  for (long long i = 0; i < n; ++i) sum += (v[i] / a) * (v[i] / a);
  return a * sqrt(sum);
}

/* sum_i a_i b_i, in four running sums (the products of a row are independent: no chain of adds). */
static double dot(const double* a, const double* b, long long n) {
  double s0 = 0.0, s1 = 0.0, s2 = 0.0, s3 = 0.0;
  long long i = 0;
  for (; i + 4 <= n; i += 4) s0 += a[i] * b[i], s1 += a[i + 1] * b[i + 1], s2 += a[i + 2] * b[i + 2], s3 += a[i + 3] * b[i + 3];
  for (; i < n; ++i) s0 += a[i] * b[i];
  return (s0 + s1) + (s2 + s3);
}

/* delta = -(H + shift I)^{-1} g by Cholesky, checked as CholeskySolver checks a solve: finite,
 * |(H + shift I) delta + g| <= rtol |g|, -g^T delta > 0 (unless g = 0). 0 on success, 1 if the
 * system counts as singular. H is symmetric, so its rows are its columns: L is built row by row
 * (L[i*N + j] = L_ij, j <= i) and every inner product runs along contiguous rows. */
static int damped_solve(const double* H, const double* g, double shift, double rtol, long long N, double* L,
                        double* delta, double* y) {
  for (long long i = 0; i < N; ++i) {
    double* row = L + i * N;
    for (long long j = 0; j <= i; ++j) {
      double s = H[i * N + j] + (i == j ? shift : 0.0) - dot(row, L + j * N, j);
      if (i == j) {
        if (!(s > 0.0) || !isfinite(s)) return 1;
        row[i] = sqrt(s);
      } else {
        row[j] = s / L[j * N + j];
      }
    }
  }
  for (long long i = 0; i < N; ++i) y[i] = (-g[i] - dot(L + i * N, y, i)) / L[i * N + i]; /* L y = -g */
  for (long long i = N - 1; i >= 0; --i) { /* L^T delta = y, column by column of L^T (rows of L) */
    delta[i] = y[i] / L[i * N + i];
    for (long long q = 0; q < i; ++q) y[q] -= L[i * N + q] * delta[i];
  }
  double residual = 0.0, b2 = 0.0, curvature = 0.0;
  for (long long i = 0; i < N; ++i) {
    if (!isfinite(delta[i])) return 1;
    double s = dot(H + i * N, delta, N) + shift * delta[i] + g[i];
    residual += s * s;
    b2 += g[i] * g[i];
    curvature -= g[i] * delta[i];
  }
  if (sqrt(residual) > rtol * sqrt(b2)) return 1;
  return b2 > 0.0 && !(curvature > 0.0);
}

/* -g^T delta - 1/2 delta^T H delta: the decrease the Gauss-Newton model predicts. */
static double model_decrease(const double* H, const double* g, const double* delta, long long N) {
  double linear = 0.0, quadratic = 0.0;
  for (long long i = 0; i < N; ++i) linear += g[i] * delta[i], quadratic += delta[i] * dot(H + i * N, delta, N);
  return -linear - 0.5 * quadratic;
}

/* A row of the history; its time counts from origin, the loop's entry. */
static void record(lm_problem* p, double origin, double f, double gnorm, double step, double damping, double rho) {
  double* row = p->history + p->records * COLUMNS;
  row[0] = f, row[1] = gnorm, row[2] = step, row[3] = now() - origin, row[4] = damping, row[5] = rho;
  p->records += 1;
}

/* Run.stop_reason after the latest record (f_prev: NAN unless the step was accepted). */
static int stop_reason(const lm_problem* p, double grad_tol, double scale, double f_prev) {
  const double* row = p->history + (p->records - 1) * COLUMNS;
  const long long nit = p->records - 1;
  if (row[1] <= grad_tol) return GRADIENT_NORM;
  if (nit > 0 && row[2] < p->min_step) return STEP_SIZE;
  if (!isnan(f_prev) && p->rel_decrease > 0 && f_prev - row[0] <= p->rel_decrease * fmax(scale, fabs(f_prev)))
    return COST_DECREASE;
  if (nit >= p->max_iterations) return MAX_ITERATIONS;
  return 0;
}

int small_lm(lm_problem* p) {
  const double origin = now();
  const long long N = p->n * p->k, m = p->m, k = p->k, s2 = p->s2;
  const size_t point = (size_t)(p->n * s2), edges = (size_t)(m * s2);
  /* One block: H and the candidate H (swapped on acceptance), L, g, g', delta, tmp, the trial
   * point, the gathered poses, two evaluations' residuals and Jacobians. */
  size_t total = 3 * (size_t)(N * N) + 4 * (size_t)N + point + 2 * edges + 2 * (size_t)(m * k) * (1 + 2 * k);
  double* block = malloc(total * sizeof(double));
  if (!block) return p->status = NO_MEMORY;
  double *H = block, *H_new = H + N * N, *L = H_new + N * N, *g = L + N * N, *g_new = g + N, *delta = g_new + N;
  double *tmp = delta + N, *trial = tmp + N, *xi = trial + point, *xj = xi + edges;
  evaluation ev = {xj + edges, 0, 0.0, 1}, ev_trial;
  ev.J = ev.r + m * k;
  ev_trial.r = ev.J + m * k * 2 * k, ev_trial.J = ev_trial.r + m * k, ev_trial.jac = 1;
  int status = 0;

  if (evaluate(p, p->x, xi, xj, &ev)) { status = KERNEL_FAILED; goto done; }
  if (!assemble(p, &ev, H, g)) { status = FALLBACK; goto done; } /* the Python path names what is not finite */
  p->nfev = p->ngev = 1;
  double f = ev.cost, gnorm = safe_norm(g, N);
  const double scale = fmin(1.0, fmax(fabs(f), gnorm * p->typical_dist));
  const double grad_tol = fmax(p->grad_rtol * gnorm, p->grad_atol * scale);
  record(p, origin, f, gnorm, NAN, NAN, NAN);
  status = stop_reason(p, grad_tol, scale, NAN);
  double lam = p->lam0, nu = p->kappa;
  int keep = 1; /* the last trial was accepted: evaluate the next one's Jacobians too */
  while (!status) {
    const double damping = lam;
    double rho = NAN, step = NAN, f_prev = NAN;
    int step_status = 0, stalled = 0, failed = 0;
    if (damped_solve(H, g, lam * scale, p->rtol, N, L, delta, tmp)) {
      failed = 1;
    } else {
      double predicted = model_decrease(H, g, delta, N);
      if (!(predicted > 0)) {
        int zero = 1;
        for (long long i = 0; i < N && zero; ++i) zero = g[i] == 0.0;
        step_status = zero ? STEP_SIZE : LINEAR_SOLVER_FAILED;
      } else {
        double biggest = 0.0;
        for (long long i = 0; i < N; ++i) biggest = fmax(biggest, fabs(delta[i]));
        if (!(biggest < p->huge)) { status = FALLBACK; break; } /* the scale-safe retraction's case */
        const double* args[2] = {p->x, delta};
        const long long arg_strides[2] = {s2, k};
        double* res[1] = {trial};
        const long long res_strides[1] = {s2};
        if (p->rplus(p->n, args, arg_strides, res, res_strides)) { status = KERNEL_FAILED; break; }
        ev_trial.jac = keep;
        if (evaluate(p, trial, xi, xj, &ev_trial)) { status = KERNEL_FAILED; break; }
        p->nfev += 1;
        double f_new = ev_trial.cost;
        if (!isfinite(f_new)) f_new = INFINITY, p->rejected += 1;
        rho = (f - f_new) / predicted;
        keep = rho > 0;
        if (rho > 0) {
          lam = fmax(lam / p->kappa, 1e-15), nu = p->kappa;
          if (!ev_trial.jac) { /* the trial kept no Jacobians: the linearization evaluates them */
            ev_trial.jac = 1;
            if (evaluate(p, trial, xi, xj, &ev_trial)) { status = KERNEL_FAILED; break; }
            p->nfev += 1;
          }
          p->ngev += 1;
          int finite = assemble(p, &ev_trial, H_new, g_new);
          if (finite) { /* moved: the candidate becomes the linearization */
            double* swap = H; H = H_new, H_new = swap;
            swap = g, g = g_new, g_new = swap;
            memcpy(p->x, trial, point * sizeof(double));
            f_prev = f, f = ev_trial.cost, gnorm = safe_norm(g, N), step = safe_norm(delta, N);
            p->moved = 1;
          } else {
            failed = 1; /* an accepted point whose linearization is not finite: rejected */
          }
        } else {
          failed = 1;
        }
      }
    }
    if (failed) { /* more damping; a failure at the largest is a collapse */
      if (lam >= p->lam_max) step_status = NO_PROGRESS, stalled = 1;
      else lam = fmin(lam * nu, p->lam_max), nu *= 2.0;
    }
    record(p, origin, f, gnorm, step, damping, rho);
    status = step_status ? step_status : stop_reason(p, grad_tol, scale, f_prev);
    int fallback = stalled ? step_status : 0;
    if (status == STEP_SIZE && !step_status) fallback = NO_PROGRESS; /* a short accepted step */
    if (fallback) { /* converged only if the model with lambda_0 sees nothing left to gain */
      double predicted = NAN;
      if (!damped_solve(H, g, p->lam0 * scale, p->rtol, N, L, delta, tmp)) predicted = model_decrease(H, g, delta, N);
      status = predicted <= p->roundoff * fmax(scale, fabs(f)) ? STEP_SIZE : fallback;
    }
  }
done:
  free(block);
  return p->status = status;
}
