/* A simplicial LDL^T factorization of B = P H P^T, up-looking, in compiled code (_ldl.py).
 *
 * B is given by its upper triangle (CSC: column k holds the rows i <= k, sorted), its values read
 * from H.data through gather (entry p of the triangle is H.data[gather[p]]); L's columns are laid
 * out by Lp (column j holds the rows below the diagonal, Lp[j + 1] - Lp[j] of them, from the
 * symbolic analysis), L unit lower triangular, D diagonal.
 *
 * Row k of L solves L[:k, :k] D[:k] l_k = B[:k, k]: its pattern is the set of nodes reached from
 * the rows of B[:k, k] up the elimination tree (the parent of j is the first row below the
 * diagonal of column j of L, which row k appends to where it is still empty: the tree is found as
 * L is, as in Liu's algorithm); they are solved for in topological order, each l_kj = y_j / d_j
 * appended to column j, and d_k = b_kk - sum_j l_kj y_j. */
#include <math.h>
#include <stdint.h>
#include <stdlib.h>
#include <string.h>

typedef int64_t i64;
typedef int32_t i32;

/* A factor: B's triangle (the caller's arrays, kept alive by it), L's layout and values, D, and
 * the workspaces (y: n doubles, zero between factorizations; mark, stack, filled: n i32 each). */
typedef struct {
  i64 n, below; /* L's entries below its diagonal */
  const i32 *bp, *bi, *gather;
  i32 *lp, *li, *mark, *stack, *filled;
  double *lx, *d, *y, *work;
} ldl_t;

void ldl_free(ldl_t* f) {
  if (!f) return;
  free(f->lp);
  free(f->lx);
  free(f);
}

/* A factor of B laid out by the column counts of L (its diagonal included), its memory allocated:
 * NULL without memory or where L's entries pass 32-bit indices. */
ldl_t* ldl_new(i64 n, const i32* bp, const i32* bi, const i32* gather, const i32* counts) {
  ldl_t* f = calloc(1, sizeof(ldl_t));
  if (!f) return NULL;
  i64 below = 0;
  for (i64 j = 0; j < n; ++j) below += counts[j] - 1;
  if (below + n >= INT32_MAX) {
    free(f);
    return NULL;
  }
  f->n = n, f->below = below, f->bp = bp, f->bi = bi, f->gather = gather;
  f->lp = malloc(sizeof(i32) * (size_t)(4 * n + 1 + below));
  f->lx = malloc(sizeof(double) * (size_t)(3 * n + below));
  if (!f->lp || !f->lx) {
    ldl_free(f);
    return NULL;
  }
  f->li = f->lp + n + 1, f->mark = f->li + below, f->stack = f->mark + n, f->filled = f->stack + n;
  f->d = f->lx + below, f->y = f->d + n, f->work = f->y + n;
  f->lp[0] = 0;
  for (i64 j = 0; j < n; ++j) f->lp[j + 1] = f->lp[j] + counts[j] - 1;
  for (i64 j = 0; j < n; ++j) f->y[j] = 0.0;
  return f;
}

/* Factors B, its values read from H.data (hx) through gather. Returns n; the first column k whose
 * pivot d_k is not a positive finite number (B is not positive definite, or holds a non-finite
 * value); or -1 where L's pattern is not the one the counts lay out (a column fills past its room,
 * or short of it: they were not B's). */
i64 ldl_factor(ldl_t* f, const double* restrict hx) {
  const i64 n = f->n;
  const i32 *restrict bp = f->bp, *restrict bi = f->bi, *restrict gather = f->gather, *restrict lp = f->lp;
  i32 *restrict li = f->li, *restrict mark = f->mark, *restrict stack = f->stack, *restrict filled = f->filled;
  double *restrict lx = f->lx, *restrict d = f->d, *restrict y = f->y;
  i64 status;
  for (i64 k = 0; k < n; ++k) mark[k] = -1, filled[k] = 0;
  for (i64 k = 0; k < n; ++k) {
    i64 top = n;
    mark[k] = (i32)k;
    for (i32 p = bp[k]; p < bp[k + 1]; ++p) { /* scatter B[:, k]; the reach of its rows, stacked */
      i32 i = bi[p];
      y[i] += hx[gather[p]];
      i64 depth = 0;
      while (mark[i] != k) { /* up the tree until a node reached already: a parent found or k */
        stack[depth++] = i;
        mark[i] = (i32)k;
        i = filled[i] ? li[lp[i]] : (i32)k;
      }
      while (depth > 0) stack[--top] = stack[--depth]; /* the path, in topological order at the top */
    }
    double dk = y[k];
    y[k] = 0.0;
    for (i64 t = top; t < n; ++t) {
      i32 j = stack[t];
      double yj = y[j];
      y[j] = 0.0;
      i32 end = lp[j] + filled[j];
      if (end >= lp[j + 1]) {
        status = -1;
        goto failed;
      }
      for (i32 p = lp[j]; p < end; ++p) y[li[p]] -= lx[p] * yj;
      double l = yj / d[j];
      dk -= l * yj;
      li[end] = (i32)k, lx[end] = l, ++filled[j];
    }
    if (!(dk > 0.0 && isfinite(dk))) {
      status = k;
      goto failed;
    }
    d[k] = dk;
  }
  for (i64 j = 0; j < n; ++j)
    if (lp[j] + filled[j] != lp[j + 1]) return -1;
  return n;
failed:
  for (i64 i = 0; i < n; ++i) y[i] = 0.0; /* as the next factorization wants it */
  return status;
}

/* x := L^{-T} D^{-1} L^{-1} x, in place, for `columns` columns of x of length n, stride apart. */
void ldl_solve(const ldl_t* f, i64 columns, i64 stride, double* x) {
  const i64 n = f->n;
  const i32 *restrict lp = f->lp, *restrict li = f->li;
  const double *restrict lx = f->lx, *restrict d = f->d;
  for (i64 c = 0; c < columns; ++c, x += stride) {
    for (i64 j = 0; j < n; ++j) {
      double xj = x[j];
      for (i32 p = lp[j]; p < lp[j + 1]; ++p) x[li[p]] -= lx[p] * xj;
    }
    for (i64 j = n - 1; j >= 0; --j) {
      double s = x[j] / d[j];
      for (i32 p = lp[j]; p < lp[j + 1]; ++p) s -= lx[p] * x[li[p]];
      x[j] = s;
    }
  }
}

/* out[perm[j]] := (B^{-1} b[perm])_j for one right-hand side: the permutations on both sides of
 * ldl_solve. */
void ldl_solve_permuted(ldl_t* f, const i64* restrict perm, const double* restrict b, double* restrict out) {
  const i64 n = f->n;
  double* restrict work = f->work;
  for (i64 j = 0; j < n; ++j) work[j] = b[perm[j]];
  ldl_solve(f, 1, n, work);
  for (i64 j = 0; j < n; ++j) out[perm[j]] = work[j];
}

/* L's entries below the diagonal. */
i64 ldl_below(const ldl_t* f) { return f->below; }

/* Copies L's layout (lp: n + 1), rows (li) and values (lx), and D (d: n). */
void ldl_read(const ldl_t* f, i32* lp, i32* li, double* lx, double* d) {
  memcpy(lp, f->lp, sizeof(i32) * (size_t)(f->n + 1));
  memcpy(li, f->li, sizeof(i32) * (size_t)f->below);
  memcpy(lx, f->lx, sizeof(double) * (size_t)f->below);
  memcpy(d, f->d, sizeof(double) * (size_t)f->n);
}
