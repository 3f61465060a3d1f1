/* The normal equations' numeric assembly, one pass over the edges (structure.py: BlockStructure._hessian
 * and _gradient, whose NumPy path writes every edge's products to a workspace and sums them into H
 * with np.add.at): each edge's products are formed in registers and added where its scatter says.
 *
 * Edge e of a factor type has the block A_e (r x W, row-major in A), residual r_e and weight w_e (1
 * where w is NULL); pos holds, flat, the position in H.data of entry (i, j) of A_e^T A_e (W x W, i
 * the row) and gpos that in g of entry j of A_e^T r_e. The sums run over k in order, and each
 * entry is added to H and g in the edges' order, as np.add.at adds them. */
#include <stdint.h>

typedef int64_t i64;
typedef int32_t i32;

#define MAX_WIDTH 32

/* H.data[pos[e, i, j]] += w_e sum_k A[e, k, i] A[e, k, j]. Returns 0, -1 where W > MAX_WIDTH. */
int hessian_add(i64 m, i64 r, i64 W, const double* restrict A, const double* restrict w, const i32* restrict pos,
                double* restrict data) {
  if (W > MAX_WIDTH) return -1;
  double p[MAX_WIDTH * MAX_WIDTH];
  i64 WW = W * W;
  for (i64 e = 0; e < m; ++e) {
    const double* a = A + e * r * W;
    const i32* q = pos + e * WW;
    for (i64 t = 0; t < WW; ++t) p[t] = 0.0;
    for (i64 k = 0; k < r; ++k) { /* the outer product of row k with itself, added */
      const double* row = a + k * W;
      for (i64 i = 0; i < W; ++i) {
        double x = row[i];
        for (i64 j = 0; j < W; ++j) p[i * W + j] += x * row[j];
      }
    }
    if (w) {
      double we = w[e];
      for (i64 t = 0; t < WW; ++t) data[q[t]] += we * p[t];
    } else {
      for (i64 t = 0; t < WW; ++t) data[q[t]] += p[t];
    }
  }
  return 0;
}

/* g[gpos[e, j]] += w_e sum_k res[e, k] A[e, k, j]. Returns 0, -1 where W > MAX_WIDTH. */
int gradient_add(i64 m, i64 r, i64 W, const double* restrict A, const double* restrict res, const double* restrict w,
                 const i32* restrict gpos, double* restrict g) {
  if (W > MAX_WIDTH) return -1;
  double p[MAX_WIDTH];
  for (i64 e = 0; e < m; ++e) {
    const double* a = A + e * r * W;
    const double* re = res + e * r;
    for (i64 j = 0; j < W; ++j) p[j] = 0.0;
    for (i64 k = 0; k < r; ++k)
      for (i64 j = 0; j < W; ++j) p[j] += re[k] * a[k * W + j];
    double we = w ? w[e] : 1.0;
    for (i64 j = 0; j < W; ++j) g[gpos[e * W + j]] += we * p[j];
  }
  return 0;
}
