/* A simplicial LDL^T factorization of B = P H P^T, up-looking, in compiled code (_ldl.py).
 *
 * B is given by its upper triangle (CSC: column k holds the rows i <= k, sorted), its values read
 * from H.data through gather (entry p of the triangle is H.data[gather[p]]); L's columns are laid
 * out by lp (column j holds the rows below the diagonal, lp[j + 1] - lp[j] of them, from the
 * symbolic analysis), L unit lower triangular, D diagonal.
 *
 * Row k of L solves L[:k, :k] D[:k] l_k = B[:k, k]: its pattern is the set of nodes reached from
 * the rows of B[:k, k] up the elimination tree (the parent of j is the first row below the
 * diagonal of column j of L, which row k appends to where it is still empty: the tree is found as
 * L is, as in Liu's algorithm); they are solved for in topological order, each l_kj = y_j / d_j
 * appended to column j, and d_k = b_kk - sum_j l_kj y_j.
 *
 * Chains: where column j + 1 is column j's parent and holds its rows but j + 1 (a variable's
 * coordinates: its diagonal block of L is dense), the columns j, j + 1 (, j + 2) reached one after
 * the other update y's rows below them in one pass, each row once: y_r - l_r,j y_j - l_r,j+1 y_j+1
 * - ..., in the order of the pass per column, so the factor is the same bit for bit. The solves
 * take them together too. */
#include <math.h>
#include <stdint.h>
#include <stdlib.h>
#include <string.h>

typedef int64_t i64;
typedef int32_t i32;

/* A factor: B's triangle (the caller's arrays, kept alive by it), L's layout and values, D, the
 * chains (chain[j]: column j + 1 continues column j), and the workspaces (y: n doubles, zero
 * between factorizations; mark, stack, filled: n i32 each; work: n doubles). */
typedef struct {
  i64 n, below; /* L's entries below its diagonal */
  const i32 *bp, *bi, *gather;
  i32 *lp, *li, *chain, *mark, *stack, *filled;
  double *lx, *d, *y, *work;
} ldl_t;

void ldl_free(ldl_t* f) {
  if (!f) return;
  free(f->lp);
  free(f->lx);
  free(f);
}

/* A factor of B laid out by the column counts of L (its diagonal included), its memory allocated:
 * NULL without memory or where L's entries pass 32-bit indices. Chains: every `width` columns a
 * variable's (width >= 2), else found from B's elimination tree (Liu's algorithm, ancestors
 * compressed) and the counts. */
ldl_t* ldl_new(i64 n, const i32* bp, const i32* bi, const i32* gather, const i32* counts, i64 width) {
  ldl_t* f = calloc(1, sizeof(ldl_t));
  if (!f) return NULL;
  i64 below = 0;
  for (i64 j = 0; j < n; ++j) below += counts[j] - 1;
  if (below + n >= INT32_MAX) {
    free(f);
    return NULL;
  }
  f->n = n, f->below = below, f->bp = bp, f->bi = bi, f->gather = gather;
  f->lp = malloc(sizeof(i32) * (size_t)(5 * n + 1 + below));
  f->lx = malloc(sizeof(double) * (size_t)(3 * n + below));
  if (!f->lp || !f->lx) {
    ldl_free(f);
    return NULL;
  }
  f->li = f->lp + n + 1, f->chain = f->li + below, f->mark = f->chain + n, f->stack = f->mark + n;
  f->filled = f->stack + n;
  f->d = f->lx + below, f->y = f->d + n, f->work = f->y + n;
  f->lp[0] = 0;
  for (i64 j = 0; j < n; ++j) f->lp[j + 1] = f->lp[j] + counts[j] - 1;
  for (i64 j = 0; j < n; ++j) f->y[j] = 0.0;
  if (width >= 2) {
    for (i64 j = 0; j < n; ++j) f->chain[j] = j + 1 < n && (j + 1) % width != 0;
  } else { /* parent in mark, ancestors in stack */
    i32 *parent = f->mark, *ancestor = f->stack;
    for (i64 k = 0; k < n; ++k) {
      parent[k] = ancestor[k] = -1;
      for (i32 p = bp[k]; p < bp[k + 1]; ++p)
        for (i32 i = bi[p]; i != -1 && i < k;) {
          i32 up = ancestor[i];
          ancestor[i] = (i32)k;
          if (up == -1) parent[i] = (i32)k;
          i = up;
        }
    }
    for (i64 j = 0; j < n; ++j) f->chain[j] = j + 1 < n && parent[j] == j + 1 && counts[j] - 1 == counts[j + 1];
  }
  return f;
}

/* Factors B, its values read from H.data (hx) through gather. Returns n; the first column k whose
 * pivot d_k is not a positive finite number (B is not positive definite, or holds a non-finite
 * value); or -1 where L's pattern is not the one the counts lay out (a column fills past its room,
 * or short of it: they were not B's). */
i64 ldl_factor(ldl_t* f, const double* restrict hx) {
  const i64 n = f->n;
  const i32 *restrict bp = f->bp, *restrict bi = f->bi, *restrict gather = f->gather, *restrict lp = f->lp;
  const i32* restrict chain = f->chain;
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
    for (i64 t = top; t < n;) {
      i32 j = stack[t], p0 = lp[j], f0 = filled[j];
      if (p0 + f0 >= lp[j + 1]) {
        status = -1;
        goto failed;
      }
      /* a chain of 2 or 3 reached in a row: column j holds j + 1 (, j + 2) first, then the rows the
       * next one holds (so far: rows < k), as their first rows and their counts say */
      int width = 1;
      if (chain[j] && t + 1 < n && stack[t + 1] == j + 1 && f0 >= 1 && li[p0] == j + 1 && filled[j + 1] == f0 - 1) {
        width = 2;
        if (chain[j + 1] && t + 2 < n && stack[t + 2] == j + 2 && f0 >= 2 && filled[j + 2] == f0 - 2 &&
            li[p0 + 1] == j + 2 && li[lp[j + 1]] == j + 2)
          width = 3;
      }
      if (width == 1) {
        double yj = y[j];
        y[j] = 0.0;
        for (i32 p = p0; p < p0 + f0; ++p) y[li[p]] -= lx[p] * yj;
        double l = yj / d[j];
        dk -= l * yj;
        li[p0 + f0] = (i32)k, lx[p0 + f0] = l, ++filled[j];
      } else if (width == 2) {
        i32 p1 = lp[j + 1], rows = f0 - 1;
        if (p1 + rows >= lp[j + 2]) {
          status = -1;
          goto failed;
        }
        double y0 = y[j], y1 = y[j + 1] - lx[p0] * y0;
        y[j] = y[j + 1] = 0.0;
        const double *a = lx + p0 + 1, *b = lx + p1;
        const i32* r = li + p1;
        for (i32 q = 0; q < rows; ++q) y[r[q]] = y[r[q]] - a[q] * y0 - b[q] * y1;
        double l0 = y0 / d[j], l1 = y1 / d[j + 1];
        dk = dk - l0 * y0 - l1 * y1;
        li[p0 + f0] = li[p1 + rows] = (i32)k, lx[p0 + f0] = l0, lx[p1 + rows] = l1;
        ++filled[j], ++filled[j + 1];
      } else {
        i32 p1 = lp[j + 1], p2 = lp[j + 2], rows = f0 - 2;
        if (p1 + rows + 1 >= lp[j + 2] || p2 + rows >= lp[j + 3]) {
          status = -1;
          goto failed;
        }
        double y0 = y[j], y1 = y[j + 1] - lx[p0] * y0;
        double y2 = y[j + 2] - lx[p0 + 1] * y0 - lx[p1] * y1;
        y[j] = y[j + 1] = y[j + 2] = 0.0;
        const double *a = lx + p0 + 2, *b = lx + p1 + 1, *c = lx + p2;
        const i32* r = li + p2;
        for (i32 q = 0; q < rows; ++q) y[r[q]] = y[r[q]] - a[q] * y0 - b[q] * y1 - c[q] * y2;
        double l0 = y0 / d[j], l1 = y1 / d[j + 1], l2 = y2 / d[j + 2];
        dk = dk - l0 * y0 - l1 * y1 - l2 * y2;
        li[p0 + f0] = li[p1 + rows + 1] = li[p2 + rows] = (i32)k;
        lx[p0 + f0] = l0, lx[p1 + rows + 1] = l1, lx[p2 + rows] = l2;
        ++filled[j], ++filled[j + 1], ++filled[j + 2];
      }
      t += width;
    }
    if (!(dk > 0.0 && isfinite(dk))) {
      status = k;
      goto failed;
    }
    d[k] = dk;
  }
  for (i64 j = 0; j < n; ++j)
    if (lp[j] + filled[j] != lp[j + 1]) return -1;
  for (i64 j = 0; j + 1 < n; ++j) /* the solves read the chains as laid out: kept where L has them */
    f->chain[j] = f->chain[j] && lp[j + 1] > lp[j] && li[lp[j]] == j + 1 && lp[j + 1] - lp[j] - 1 == lp[j + 2] - lp[j + 1];
  return n;
failed:
  for (i64 i = 0; i < n; ++i) y[i] = 0.0; /* as the next factorization wants it */
  return status;
}

/* x := L^{-T} D^{-1} L^{-1} x, in place, for `columns` columns of x of length n, stride apart. */
void ldl_solve(const ldl_t* f, i64 columns, i64 stride, double* x) {
  const i64 n = f->n;
  const i32 *restrict lp = f->lp, *restrict li = f->li, *restrict chain = f->chain;
  const double *restrict lx = f->lx, *restrict d = f->d;
  for (i64 c = 0; c < columns; ++c, x += stride) {
    for (i64 j = 0; j < n;) { /* L z = x: a chain's columns (its rows below them shared) together */
      i32 p0 = lp[j], p1 = lp[j + 1];
      if (j + 2 < n && chain[j] && chain[j + 1]) {
        i32 p2 = lp[j + 2];
        double x0 = x[j], x1 = x[j + 1] - lx[p0] * x0, x2 = x[j + 2] - lx[p0 + 1] * x0 - lx[p1] * x1;
        x[j + 1] = x1, x[j + 2] = x2;
        const double *a = lx + p0 + 2, *b = lx + p1 + 1, *e = lx + p2;
        const i32* r = li + p2;
        for (i32 q = 0; q < lp[j + 3] - p2; ++q) x[r[q]] = x[r[q]] - a[q] * x0 - b[q] * x1 - e[q] * x2;
        j += 3;
      } else if (j + 1 < n && chain[j]) {
        double x0 = x[j], x1 = x[j + 1] - lx[p0] * x0;
        x[j + 1] = x1;
        const double *a = lx + p0 + 1, *b = lx + p1;
        const i32* r = li + p1;
        for (i32 q = 0; q < lp[j + 2] - p1; ++q) x[r[q]] = x[r[q]] - a[q] * x0 - b[q] * x1;
        j += 2;
      } else {
        double x0 = x[j];
        for (i32 p = p0; p < p1; ++p) x[li[p]] -= lx[p] * x0;
        j += 1;
      }
    }
    for (i64 j = n - 1; j >= 0;) { /* D Lᵀ x = z, from the last column: a chain's columns together */
      if (j >= 2 && chain[j - 1] && chain[j - 2]) {
        i32 pa = lp[j - 2], pb = lp[j - 1], pc = lp[j];
        const double *a = lx + pa + 2, *b = lx + pb + 1, *e = lx + pc;
        const i32* r = li + pc;
        double ta = 0.0, tb = 0.0, tc = 0.0;
        for (i32 q = 0; q < lp[j + 1] - pc; ++q) {
          double xr = x[r[q]];
          ta += a[q] * xr, tb += b[q] * xr, tc += e[q] * xr;
        }
        double sc = x[j] / d[j] - tc;
        double sb = x[j - 1] / d[j - 1] - tb - lx[pb] * sc;
        double sa = x[j - 2] / d[j - 2] - ta - lx[pa] * sb - lx[pa + 1] * sc;
        x[j] = sc, x[j - 1] = sb, x[j - 2] = sa;
        j -= 3;
      } else if (j >= 1 && chain[j - 1]) {
        i32 pa = lp[j - 1], pb = lp[j];
        const double *a = lx + pa + 1, *b = lx + pb;
        const i32* r = li + pb;
        double ta = 0.0, tb = 0.0;
        for (i32 q = 0; q < lp[j + 1] - pb; ++q) {
          double xr = x[r[q]];
          ta += a[q] * xr, tb += b[q] * xr;
        }
        double sb = x[j] / d[j] - tb;
        double sa = x[j - 1] / d[j - 1] - ta - lx[pa] * sb;
        x[j] = sb, x[j - 1] = sa;
        j -= 2;
      } else {
        double s = x[j] / d[j];
        for (i32 p = lp[j]; p < lp[j + 1]; ++p) s -= lx[p] * x[li[p]];
        x[j] = s;
        j -= 1;
      }
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
