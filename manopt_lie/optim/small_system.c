/* Gauss-Newton, Levenberg-Marquardt and Powell's dogleg on a small pose graph, every iteration
 * in compiled code.
 *
 * The iterations of manopt_lie.optim's GaussNewton, LevenbergMarquardt and Dogleg — their steps,
 * acceptance and updates, the stopping rule and the collapse test of the shared loop
 * (NonlinearLeastSquares._solve, Run) — for one between factor on SE(2) or SE(3) whose kernels
 * are the library's native ones, passed in as function pointers (manopt_lie/_native.py's batch
 * drivers). The caller (manopt_lie/optim/_small_system.py) checks that a problem qualifies, lays
 * out the problem struct and turns the history into a result; this file holds no policy of its
 * own, and its comments name the Python it mirrors.
 *
 * H = sum_e A_e^T A_e and g = sum_e A_e^T r_e are stored dense (at most 768 unknowns: the caller's
 * DENSE_UNKNOWNS and MAX_UNKNOWNS), in an order of the poses that keeps H banded (reverse
 * Cuthill-McKee, from the caller); the columns of fixed poses are zero in A_e and 1 on their
 * diagonal, as LeastSquaresProblem builds them. Solves are LAPACK's, dense or banded, and checked
 * as CholeskySolver checks a solution (its random probe aside).
 */
#include <math.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

typedef int (*batch_fn)(long long m, const double** arg, const long long* arg_stride, double** res,
                        const long long* res_stride);
/* LAPACK's Cholesky factorization and solve, dense and banded, as SciPy ships them
 * (scipy.linalg.cython_lapack): the dense ones are what the Python loop's dense solves call. */
typedef void (*potrf_fn)(char* uplo, int* n, double* a, int* lda, int* info);
typedef void (*potrs_fn)(char* uplo, int* n, int* nrhs, double* a, int* lda, double* b, int* ldb, int* info);
typedef void (*pbtrf_fn)(char* uplo, int* n, int* kd, double* ab, int* ldab, int* info);
typedef void (*pbtrs_fn)(char* uplo, int* n, int* kd, int* nrhs, double* ab, int* ldab, double* b, int* ldb, int* info);

enum { GRADIENT_NORM = 1, COST_DECREASE = 2, STEP_SIZE = 3, MAX_ITERATIONS = 4, LINE_SEARCH_FAILED = 6,
       LINEAR_SOLVER_FAILED = 7, NO_PROGRESS = 9, NON_FINITE = 10, FALLBACK = -1, NO_MEMORY = -2 };
enum { GAUSS_NEWTON = 0, LEVENBERG_MARQUARDT = 1, DOGLEG = 2 };
enum { COLUMNS = 8, EXTRAS = 4 }; /* history: f, |grad|, step, time, then the method's extras */

typedef struct {
  /* the graph */
  long long n, m, s2, k;          /* poses, edges, entries of a pose's matrix (9, 16), its tangent dim (3, 6) */
  const long long* edges;          /* (m, 2) */
  const unsigned char* fixed;      /* (n,) */
  const double* z;                 /* (m, s2): the inverse measurements, rows of their matrices */
  const double* sqrt_info;         /* (k*k) shared, (m, k*k) per edge, or NULL (unit noise) */
  long long sqrt_info_stride;      /* 0 (shared) or k*k */
  batch_fn between, log, rplus;    /* (xi, xj, z[, L]) -> (r, [J_i | J_j]); -> r; (x, tau) -> x Exp(tau) */
  potrf_fn potrf;
  potrs_fn potrs;
  pbtrf_fn pbtrf;
  pbtrs_fn pbtrs;
  /* the order of the unknowns: pose v's coordinates at position[v]*k..; H's half bandwidth in it
   * (N - 1: dense, factored by potrf; less: banded, by pbtrf) */
  const long long* position;
  long long kd;
  /* the run's settings */
  double rtol, grad_rtol, grad_atol, min_step, rel_decrease, typical_dist, roundoff, huge;
  long long max_iterations;
  /* the method and its settings: GN (c1, backtracks), LM (lam0, lam_max, kappa), dogleg (radius0, NAN: none) */
  long long method, max_backtracks;
  double c1, lam0, lam_max, kappa, radius0;
  /* in: x0; out: the last point */
  double* x;                       /* (n, s2) */
  /* out */
  double* history;                 /* (max_iterations + 1, COLUMNS) */
  long long records, nfev, ngev, rejected, moved;
  int status;
} nls_problem;

typedef struct { /* one point's evaluation: residuals, Jacobians, cost */
  double *r, *J, cost;
  int jac;
} evaluation;

typedef struct { /* what a method's step returns (nonlinear_least_squares._Step) */
  int accepted, status, stalled;
  double f, step, predicted, extra[EXTRAS];
} step_result;

typedef struct { /* the loop's state */
  nls_problem* p;
  long long N;
  double *H, *H_new, *L, *g, *g_new, *delta, *tmp, *trial, *xi, *xj, *gauss_newton, *cauchy;
  evaluation ev, ev_trial;
  double f, gnorm, scale;
  int keep;                        /* the last trial was accepted: evaluate the next one's Jacobians too */
  double lam, nu;                  /* LM: the damping and its growth */
  double radius, shift;            /* dogleg: the radius (NAN: not set), the Gauss-Newton leg's shift mu */
  int legs, has_gauss_newton, has_cauchy; /* dogleg: the legs are of the current linearization */
} state;

static double now(void) {
  struct timespec t;
  clock_gettime(CLOCK_MONOTONIC, &t);
  return (double)t.tv_sec + 1e-9 * (double)t.tv_nsec;
}

/* sum_i a_i b_i, in four running sums (the products are independent: no chain of adds). */
static double dot(const double* a, const double* b, long long n) {
  double s0 = 0.0, s1 = 0.0, s2 = 0.0, s3 = 0.0;
  long long i = 0;
  for (; i + 4 <= n; i += 4) s0 += a[i] * b[i], s1 += a[i + 1] * b[i + 1], s2 += a[i + 2] * b[i + 2], s3 += a[i + 3] * b[i + 3];
  for (; i < n; ++i) s0 += a[i] * b[i];
  return (s0 + s1) + (s2 + s3);
}

static double norm(const double* v, long long n) { return sqrt(dot(v, v, n)); }

/* sqrt(sum v_i^2), rescaled by max |v_i| when the sum leaves [1e-250, 1e250] (Run.norm). */
static double safe_norm(const double* v, long long n) {
  double sum = dot(v, v, n);
  if (sum >= 1e-250 && sum <= 1e250) return sqrt(sum);
  double a = 0.0;
  for (long long i = 0; i < n; ++i) a = fmax(a, fabs(v[i]));
  if (a == 0.0 || !isfinite(a)) return isnan(sum) ? NAN : a;
  sum = 0.0;
  for (long long i = 0; i < n; ++i) sum += (v[i] / a) * (v[i] / a);
  return a * sqrt(sum);
}

/* The residuals (and with jac their Jacobians) of every edge at the poses x; 0, or nonzero if a
 * kernel failed. The cost is 1/2 |r|^2 (not finite when a residual is not). */
static int evaluate(const nls_problem* p, const double* x, double* xi, double* xj, evaluation* out) {
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
  out->cost = 0.5 * dot(out->r, out->r, m * k);
  if (out->jac) { /* the fixed poses' columns: zero, so their update is exactly zero */
    for (long long e = 0; e < m; ++e)
      for (int s = 0; s < 2; ++s)
        if (p->fixed[p->edges[2 * e + s]])
          for (long long row = 0; row < k; ++row) memset(out->J + e * 2 * k * k + row * 2 * k + s * k, 0, k * sizeof(double));
  }
  return 0;
}

/* H = sum_e A_e^T A_e (+1 on the fixed poses' diagonal) and g = sum_e A_e^T r_e, A_e = [J_i | J_j]:
 * each edge's products summed row by row of A_e into a block (exactly symmetric), then added into
 * H; whether the cost, g and the Jacobians are finite (Linearization.is_finite). */
static int assemble(const nls_problem* p, const evaluation* ev, double* H, double* g) {
  const long long k = p->k, w = 2 * k, N = p->n * k;
  for (long long i = 0; i < N; ++i) { /* the band only: nothing is added outside it */
    const long long lo = i > p->kd ? i - p->kd : 0, hi = i + p->kd + 1 < N ? i + p->kd + 1 : N;
    memset(H + i * N + lo, 0, (hi - lo) * sizeof(double));
  }
  memset(g, 0, N * sizeof(double));
  long long col[12];
  double block[144], ga[12];
  int finite = isfinite(ev->cost);
  for (long long e = 0; e < p->m; ++e) {
    const double* A = ev->J + e * k * w;
    const double* r = ev->r + e * k;
    for (long long a = 0; a < w; ++a) col[a] = p->position[p->edges[2 * e + a / k]] * k + a % k;
    memset(block, 0, w * w * sizeof(double));
    memset(ga, 0, w * sizeof(double));
    for (long long row = 0; row < k; ++row) {
      const double* Ar = A + row * w;
      for (long long a = 0; a < w; ++a) {
        finite &= isfinite(Ar[a]);
        ga[a] += Ar[a] * r[row];
        for (long long b = 0; b < w; ++b) block[a * w + b] += Ar[a] * Ar[b];
      }
    }
    for (long long a = 0; a < w; ++a) {
      g[col[a]] += ga[a];
      double* Hrow = H + col[a] * N;
      for (long long b = 0; b < w; ++b) Hrow[col[b]] += block[a * w + b];
    }
  }
  for (long long v = 0; v < p->n; ++v)
    if (p->fixed[v])
      for (long long c = p->position[v] * k; c < (p->position[v] + 1) * k; ++c) H[c * N + c] += 1.0;
  for (long long i = 0; i < N && finite; ++i) finite = isfinite(g[i]);
  return finite;
}

/* Row i of H times v, over the band (H is zero outside it). */
static double row_product(const nls_problem* p, const double* H, const double* v, long long i) {
  const long long N = p->n * p->k, lo = i > p->kd ? i - p->kd : 0, hi = i + p->kd + 1 < N ? i + p->kd + 1 : N;
  return dot(H + i * N + lo, v + lo, hi - lo);
}

/* delta = -(H + shift I)^{-1} g by LAPACK's Cholesky, dense (potrf) or banded (pbtrf), the factor
 * in L; checked as CholeskySolver checks a solve: finite, |(H + shift I) delta + g| <= rtol |g|,
 * -g^T delta > 0 (unless g = 0). 0 on success, 1 if the system counts as singular. H is symmetric:
 * its rows are its columns, whichever order LAPACK reads. */
static int damped_solve(const nls_problem* p, const double* H, const double* g, double shift, long long N, double* L,
                        double* delta) {
  char lower = 'L';
  int n = (int)N, kd = (int)p->kd, ldab = kd + 1, one = 1, info = 0;
  for (long long i = 0; i < N; ++i) delta[i] = -g[i];
  if (p->kd >= N - 1) {
    memcpy(L, H, N * N * sizeof(double));
    for (long long i = 0; i < N; ++i) L[i * N + i] += shift;
    p->potrf(&lower, &n, L, &n, &info);
    if (!info) p->potrs(&lower, &n, &one, L, &n, delta, &n, &info);
  } else { /* column j of the lower band: ab[(i - j) + j (kd + 1)] = H_ij, j <= i <= j + kd */
    for (long long j = 0; j < N; ++j)
      for (long long i = j; i <= j + kd && i < N; ++i) L[(i - j) + j * ldab] = H[i * N + j] + (i == j ? shift : 0.0);
    p->pbtrf(&lower, &n, &kd, L, &ldab, &info);
    if (!info) p->pbtrs(&lower, &n, &kd, &one, L, &ldab, delta, &n, &info);
  }
  if (info) return 1;
  double residual = 0.0, b2 = 0.0, curvature = 0.0;
  for (long long i = 0; i < N; ++i) {
    if (!isfinite(delta[i])) return 1;
    double s = row_product(p, H, delta, i) + shift * delta[i] + g[i];
    residual += s * s;
    b2 += g[i] * g[i];
    curvature -= g[i] * delta[i];
  }
  if (sqrt(residual) > p->rtol * sqrt(b2)) return 1;
  return b2 > 0.0 && !(curvature > 0.0);
}

/* -g^T delta - 1/2 delta^T H delta: the decrease the Gauss-Newton model predicts (model_decrease). */
static double model_decrease(const nls_problem* p, const double* H, const double* g, const double* delta, long long N) {
  double linear = 0.0, quadratic = 0.0;
  for (long long i = 0; i < N; ++i) linear += g[i] * delta[i], quadratic += delta[i] * row_product(p, H, delta, i);
  return -linear - 0.5 * quadratic;
}

/* _no_descent: a stationary point (g = 0) or a failed solve. */
static int no_descent(const double* g, long long N) {
  for (long long i = 0; i < N; ++i)
    if (g[i] != 0.0) return LINEAR_SOLVER_FAILED;
  return STEP_SIZE;
}

/* The cost at R_x(alpha delta) (Run.cost: +inf, counted, if it is not finite), the point in
 * s->trial, its Jacobians kept with keep; 0, or the status that ends the compiled loop. */
static int trial_cost(state* s, double alpha, int keep, double* f) {
  nls_problem* p = s->p;
  double biggest = 0.0; /* alpha delta, pose by pose in the poses' order */
  for (long long v = 0; v < p->n; ++v)
    for (long long a = 0; a < p->k; ++a) {
      const double t = alpha * s->delta[p->position[v] * p->k + a];
      s->tmp[v * p->k + a] = t, biggest = fmax(biggest, fabs(t));
    }
  if (!(biggest < p->huge)) return FALLBACK; /* the scale-safe retraction's case (LieGroupManifold.retr) */
  const double* args[2] = {p->x, s->tmp};
  const long long arg_strides[2] = {p->s2, p->k};
  double* res[1] = {s->trial};
  const long long res_strides[1] = {p->s2};
  if (p->rplus(p->n, args, arg_strides, res, res_strides)) return FALLBACK;
  s->ev_trial.jac = keep;
  if (evaluate(p, s->trial, s->xi, s->xj, &s->ev_trial)) return FALLBACK;
  p->nfev += 1;
  *f = s->ev_trial.cost;
  if (!isfinite(*f)) *f = INFINITY, p->rejected += 1;
  return 0;
}

/* The linearization at the accepted trial point (NonlinearLeastSquares._linearize): 1 if it is
 * finite and the run moved there, 0 if not (the run stays), negative to end the compiled loop. */
static int move(state* s) {
  nls_problem* p = s->p;
  if (!s->ev_trial.jac) { /* the trial kept no Jacobians: the linearization evaluates them */
    s->ev_trial.jac = 1;
    if (evaluate(p, s->trial, s->xi, s->xj, &s->ev_trial)) return FALLBACK;
    p->nfev += 1;
  }
  p->ngev += 1;
  if (!assemble(p, &s->ev_trial, s->H_new, s->g_new)) return 0;
  double* swap = s->H;
  s->H = s->H_new, s->H_new = swap;
  swap = s->g, s->g = s->g_new, s->g_new = swap;
  memcpy(p->x, s->trial, (size_t)(p->n * p->s2) * sizeof(double));
  s->f = s->ev_trial.cost, s->gnorm = safe_norm(s->g, s->N), s->legs = 0;
  p->moved = 1;
  return 1;
}

static step_result rejected(const state* s) {
  step_result r = {0, 0, 0, s->f, NAN, NAN, {NAN, NAN, NAN, NAN}};
  return r;
}

/* ---- Gauss-Newton (GaussNewton._step, line_search.armijo) ---- */

static int gauss_newton_step(state* s, step_result* r) {
  nls_problem* p = s->p;
  *r = rejected(s);
  r->extra[0] = 0.0; /* alpha */
  if (damped_solve(p, s->H, s->g, 0.0, s->N, s->L, s->delta)) return FALLBACK; /* GN raises */
  const double slope = dot(s->g, s->delta, s->N), d_norm = norm(s->delta, s->N);
  if (!(slope < 0)) {
    r->status = no_descent(s->g, s->N);
    return 0;
  }
  double alpha = 1.0, f_new;
  for (long long trial = 0; trial <= p->max_backtracks; ++trial, alpha *= 0.5) {
    int failed = trial_cost(s, alpha, trial == 0, &f_new); /* the full step's Jacobians kept, no backtrack's */
    if (failed) return failed;
    if (f_new <= s->f + p->c1 * alpha * slope && f_new < s->f) {
      r->accepted = 1, r->f = f_new, r->step = alpha * d_norm, r->extra[0] = alpha;
      return 0;
    }
  }
  r->status = LINE_SEARCH_FAILED, r->stalled = 1, r->predicted = model_decrease(s->p, s->H, s->g, s->delta, s->N);
  return 0;
}

/* ---- Levenberg-Marquardt (LevenbergMarquardt._step, _fail) ---- */

static void lm_fail(state* s, step_result* r) {
  nls_problem* p = s->p;
  if (s->lam >= p->lam_max) r->status = NO_PROGRESS, r->stalled = 1;
  else s->lam = fmin(s->lam * s->nu, p->lam_max), s->nu *= 2.0;
}

static int lm_step(state* s, step_result* r) {
  nls_problem* p = s->p;
  *r = rejected(s);
  r->extra[0] = s->lam; /* damping; extra[1]: rho */
  if (damped_solve(p, s->H, s->g, s->lam * s->scale, s->N, s->L, s->delta)) {
    lm_fail(s, r);
    return 0;
  }
  const double predicted = model_decrease(s->p, s->H, s->g, s->delta, s->N);
  if (!(predicted > 0)) {
    r->status = no_descent(s->g, s->N);
    return 0;
  }
  double f_new;
  int failed = trial_cost(s, 1.0, s->keep, &f_new);
  if (failed) return failed;
  const double rho = (s->f - f_new) / predicted;
  r->extra[1] = rho;
  s->keep = rho > 0;
  if (rho > 0) {
    s->lam = fmax(s->lam / p->kappa, 1e-15), s->nu = p->kappa;
    r->accepted = 1, r->f = f_new, r->step = norm(s->delta, s->N);
  } else {
    lm_fail(s, r);
  }
  return 0;
}

/* ---- Powell's dogleg (Dogleg._legs, dogleg_step, Dogleg._step, _fail) ---- */

static const double SHIFTS[] = {0.0, 1e-8, 1e-6, 1e-4, 1e-2, 1.0, 1e2};

static void dogleg_legs(state* s) {
  nls_problem* p = s->p;
  const long long N = s->N;
  if (s->legs) return;
  s->has_gauss_newton = 0, s->shift = NAN;
  for (size_t i = 0; i < sizeof SHIFTS / sizeof SHIFTS[0] && !s->has_gauss_newton; ++i)
    if (!damped_solve(p, s->H, s->g, SHIFTS[i] * s->scale, N, s->L, s->gauss_newton))
      s->has_gauss_newton = 1, s->shift = SHIFTS[i];
  double curvature = 0.0;
  for (long long i = 0; i < N; ++i) curvature += s->g[i] * row_product(p, s->H, s->g, i);
  const double gg = dot(s->g, s->g, N);
  s->has_cauchy = curvature > 0;
  for (long long i = 0; i < N && s->has_cauchy; ++i) s->cauchy[i] = -(gg / curvature) * s->g[i];
  s->legs = 1;
}

/* The dogleg step of radius Delta into s->delta; its kind (0 Gauss-Newton, 1 dogleg, 2 Cauchy). */
static double dogleg_path(state* s, double radius) {
  const long long N = s->N;
  double *a = s->cauchy, *b = s->gauss_newton, *d = s->delta;
  if (s->has_gauss_newton && norm(b, N) <= radius) {
    memcpy(d, b, N * sizeof(double));
    return 0.0;
  }
  const double a_norm = s->has_cauchy ? norm(a, N) : INFINITY;
  if (s->has_cauchy && (!s->has_gauss_newton || a_norm >= radius)) {
    const double c = a_norm <= radius ? 1.0 : radius / a_norm;
    for (long long i = 0; i < N; ++i) d[i] = a_norm <= radius ? a[i] : a[i] * c;
    return 2.0;
  }
  if (!s->has_gauss_newton || !s->has_cauchy) {
    const double c = -radius / norm(s->g, N);
    for (long long i = 0; i < N; ++i) d[i] = s->g[i] * c;
    return 2.0;
  }
  double ad = 0.0, dd = 0.0;
  for (long long i = 0; i < N; ++i) d[i] = b[i] - a[i], ad += a[i] * d[i], dd += d[i] * d[i];
  const double room = radius * radius - a_norm * a_norm, root = sqrt(ad * ad + dd * room);
  const double tau = fmin(fmax(ad > 0 ? room / (ad + root) : (root - ad) / dd, 0.0), 1.0);
  for (long long i = 0; i < N; ++i) d[i] = a[i] + tau * d[i];
  return 1.0;
}

/* A rejected step; a radius below min_step is a collapse, judged by the Gauss-Newton model. */
static void dogleg_fail(state* s, step_result* r, int with_model) {
  if (s->radius < s->p->min_step || s->radius == 0) {
    r->status = NO_PROGRESS, r->stalled = 1;
    if (with_model && s->has_gauss_newton) r->predicted = model_decrease(s->p, s->H, s->g, s->gauss_newton, s->N);
  }
}

static int dogleg_step(state* s, step_result* r) {
  const long long N = s->N;
  *r = rejected(s);
  dogleg_legs(s);
  if (isnan(s->radius)) {
    const double* first = s->has_gauss_newton ? s->gauss_newton : s->has_cauchy ? s->cauchy : NULL;
    s->radius = first ? norm(first, N) : 1.0;
    if (!(s->radius > 0 && isfinite(s->radius))) s->radius = 1.0;
  }
  const double radius = s->radius;
  r->extra[0] = radius, r->extra[1] = s->shift; /* radius, gauss_newton_shift; extra[2]: kind, [3]: rho */
  if (no_descent(s->g, N) == STEP_SIZE) {
    r->status = STEP_SIZE;
    return 0;
  }
  r->extra[2] = dogleg_path(s, radius);
  const double predicted = model_decrease(s->p, s->H, s->g, s->delta, N);
  if (!(predicted > 0)) {
    r->status = no_descent(s->g, N);
    return 0;
  }
  double f_new;
  int failed = trial_cost(s, 1.0, s->keep, &f_new);
  if (failed) return failed;
  const double rho = (s->f - f_new) / predicted, length = norm(s->delta, N);
  r->extra[3] = rho;
  s->keep = rho > 0;
  if (rho < 0.25 || !isfinite(rho)) s->radius = 0.25 * length;
  else if (rho > 0.75) s->radius = fmax(radius, 3.0 * length);
  if (rho > 0) r->accepted = 1, r->f = f_new, r->step = length;
  else dogleg_fail(s, r, 1);
  return 0;
}

/* ---- the loop (NonlinearLeastSquares._solve) ---- */

/* A row of the history; its time counts from origin, the loop's entry. */
static void record(nls_problem* p, double origin, double f, double gnorm, double step, const double* extra) {
  double* row = p->history + p->records * COLUMNS;
  row[0] = f, row[1] = gnorm, row[2] = step, row[3] = now() - origin;
  for (int i = 0; i < EXTRAS; ++i) row[4 + i] = extra ? extra[i] : NAN;
  p->records += 1;
}

/* Run.stop_reason after the latest record (f_prev: NAN unless the step was accepted). */
static int stop_reason(const nls_problem* p, double grad_tol, double scale, double f_prev) {
  const double* row = p->history + (p->records - 1) * COLUMNS;
  const long long nit = p->records - 1;
  if (row[1] <= grad_tol) return GRADIENT_NORM;
  if (nit > 0 && row[2] < p->min_step) return STEP_SIZE;
  if (!isnan(f_prev) && p->rel_decrease > 0 && f_prev - row[0] <= p->rel_decrease * fmax(scale, fabs(f_prev)))
    return COST_DECREASE;
  if (nit >= p->max_iterations) return MAX_ITERATIONS;
  return 0;
}

/* The decrease the model predicts for the method's step at the point (NAN if it cannot be
 * solved): Gauss-Newton's, LM's with lambda_0 (_predicted_decrease). */
static double predicted_decrease(state* s) {
  const double shift = s->p->method == LEVENBERG_MARQUARDT ? s->p->lam0 * s->scale : 0.0;
  if (damped_solve(s->p, s->H, s->g, shift, s->N, s->L, s->delta)) return NAN;
  return model_decrease(s->p, s->H, s->g, s->delta, s->N);
}

int small_system(nls_problem* p) {
  const double origin = now();
  const long long N = p->n * p->k, m = p->m, k = p->k;
  const size_t point = (size_t)(p->n * p->s2), edges = (size_t)(m * p->s2), nn = (size_t)(N * N);
  const size_t evaluation_size = (size_t)(m * k) * (size_t)(1 + 2 * k);
  /* One block: H and the candidate H (swapped on acceptance), L; g, g', delta, tmp, the two
   * dogleg legs; the trial point, the gathered poses; two evaluations. */
  double* block = malloc((3 * nn + 6 * (size_t)N + point + 2 * edges + 2 * evaluation_size) * sizeof(double));
  if (!block) return p->status = NO_MEMORY;
  state s = {p, N};
  s.H = block, s.H_new = s.H + nn, s.L = s.H_new + nn, s.g = s.L + nn, s.g_new = s.g + N, s.delta = s.g_new + N;
  s.tmp = s.delta + N, s.gauss_newton = s.tmp + N, s.cauchy = s.gauss_newton + N, s.trial = s.cauchy + N;
  s.xi = s.trial + point, s.xj = s.xi + edges;
  s.ev.r = s.xj + edges, s.ev.J = s.ev.r + m * k, s.ev.jac = 1;
  s.ev_trial.r = s.ev.r + evaluation_size, s.ev_trial.J = s.ev_trial.r + m * k;
  s.keep = 1, s.lam = p->lam0, s.nu = p->kappa, s.radius = p->radius0;
  int status = 0;
  if (evaluate(p, p->x, s.xi, s.xj, &s.ev) || !assemble(p, &s.ev, s.H, s.g)) {
    status = FALLBACK; /* the Python loop names what is not finite, or raises the kernel's failure */
    goto done;
  }
  p->nfev = p->ngev = 1;
  s.f = s.ev.cost, s.gnorm = safe_norm(s.g, N);
  s.scale = fmin(1.0, fmax(fabs(s.f), s.gnorm * p->typical_dist));
  const double grad_tol = fmax(p->grad_rtol * s.gnorm, p->grad_atol * s.scale);
  record(p, origin, s.f, s.gnorm, NAN, NULL);
  status = stop_reason(p, grad_tol, s.scale, NAN);
  while (!status) {
    step_result r;
    double f_prev = NAN;
    int failed = p->method == GAUSS_NEWTON ? gauss_newton_step(&s, &r)
                 : p->method == LEVENBERG_MARQUARDT ? lm_step(&s, &r) : dogleg_step(&s, &r);
    if (failed) { status = failed; break; }
    if (r.accepted) {
      const double f_old = s.f;
      int moved = move(&s);
      if (moved < 0) { status = moved; break; }
      if (moved) {
        f_prev = f_old;
      } else { /* an accepted point whose linearization is not finite (_reject_nonfinite) */
        const double length = r.step;
        r.accepted = 0, r.step = NAN;
        if (p->method == GAUSS_NEWTON) r.status = NON_FINITE;
        else if (p->method == LEVENBERG_MARQUARDT) lm_fail(&s, &r);
        else s.radius = 0.25 * (isfinite(length) ? length : (isnan(s.radius) || s.radius == 0 ? 1.0 : s.radius)), dogleg_fail(&s, &r, 0);
      }
    }
    record(p, origin, s.f, s.gnorm, r.step, r.extra);
    status = r.status ? r.status : stop_reason(p, grad_tol, s.scale, f_prev);
    int fallback = r.stalled ? r.status : 0;
    if (status == STEP_SIZE && !r.status) fallback = NO_PROGRESS; /* a short accepted step */
    if (fallback) { /* the step collapsed: converged only if nothing is left to gain */
      double predicted = isnan(r.predicted) ? predicted_decrease(&s) : r.predicted;
      status = predicted <= p->roundoff * fmax(s.scale, fabs(s.f)) ? STEP_SIZE : fallback;
    }
  }
done:
  free(block);
  return p->status = status;
}
