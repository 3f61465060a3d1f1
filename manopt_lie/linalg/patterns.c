/* A solve's set-up at the scale of the variables: the index arrays of a block structure, the
 * triangle CHOLMOD factors, and the symbolic factorization of the variables' graph.
 *
 * build_structure checks the edges as _factors.check_edges does, then builds (block_pattern,
 * layout, expand_pattern, factor_scatter) what manopt_lie/linalg/_patterns_numpy.py
 * (sparse_pattern, factor_scatter, and HessianScatter's positions) builds with NumPy, and
 * permuted_triangle what _triangles.py's permuted_block_triangle builds: the same arrays, entry for
 * entry (tests/linalg/test_patterns.py), in a few passes over the blocks instead of a few dozen
 * NumPy calls over the entries.
 * block_symbolic and expand_supernodes make B's symbolic factor from the variables' (_cholmod.py,
 * Cholmod._analyze_blocks). early.c, compiled with this file into one library, runs the build,
 * AMD, block_symbolic and permuted_triangle on a worker thread while Python linearizes (_early.py).
 * The callers (manopt_lie/linalg/_patterns.py, _early.py) size every output and use these only
 * where every index of H fits in 32 bits.
 *
 * Notation (structure.py's): variable v has dimension d_v and owns coordinates o_v ... o_v + d_v - 1;
 * block k = (w, v) holds the rows of w in the columns of v; each column of v has length L_v (the
 * dimensions of the rows of v's blocks), v's columns start at base_v, and block k starts
 * within_k down each of them: entry (o_w + i, o_v + j) sits at base_v + j L_v + within_k + i.
 */
#include <stdint.h>
#include <stdlib.h>
#include <string.h>

typedef int64_t i64;
typedef int32_t i32;

static int ascending(const void* a, const void* b) {
  i64 x = *(const i64*)a, y = *(const i64*)b;
  return (x > y) - (x < y);
}

static void sort(i64* a, i64 n) {
  if (n > 24) {
    qsort(a, (size_t)n, sizeof(i64), ascending);
    return;
  }
  for (i64 i = 1; i < n; ++i) { /* a column of a pose graph holds a handful of blocks */
    i64 x = a[i], j = i - 1;
    for (; j >= 0 && a[j] > x; --j) a[j + 1] = a[j];
    a[j + 1] = x;
  }
}

/* The variables' graph: block k of column v for every pair of slots (s, t) of every edge (rows of
 * slot s in the columns of slot t) and every diagonal block, sorted and without repeats, as block
 * CSC (bptr: nv + 1, brows: room for nv + sum_f m_f a_f (a_f - 1), filled with the nb blocks
 * first); and blocks[f][(t m_f + e) a_f + s], the block of edge e's slots (s, t); all 32-bit (the
 * caller checks that H's order fits). Each column's candidates (its diagonal block, and the other
 * slots of its edges: a slot's own block is the diagonal one) are gathered with where their block
 * goes; the distinct rows are told apart by a mark per row and only they are sorted. Returns nb,
 * -1 without memory. */
static i64 block_pattern(i64 nv, i64 n_factors, const i64* m, const i64* arity, const i64* const* ids, i32* bptr,
                         i32* brows, i32* const* blocks) {
  i64 candidates = nv; /* an edge's blocks off the diagonal; its slots' own are the diagonal blocks */
  for (i64 f = 0; f < n_factors; ++f) candidates += m[f] * arity[f] * (arity[f] - 1);
  i64* fill = calloc((size_t)(4 * nv + 1), sizeof(i64));
  i32** dest = malloc(sizeof(i32*) * (size_t)candidates); /* where each candidate's block index goes */
  if (!fill || !dest) {
    free(fill), free(dest);
    return -1;
  }
  i64 *mark = fill + nv + 1, *where = mark + nv; /* per row: the column that saw it last, its block */
  i64* diagonal = where + nv;                      /* per column: its diagonal block */
  for (i64 v = 0; v < nv; ++v) fill[v + 1] = 1, mark[v] = -1; /* the diagonal block */
  for (i64 f = 0; f < n_factors; ++f)
    for (i64 e = 0; e < m[f]; ++e)
      for (i64 t = 0; t < arity[f]; ++t) fill[ids[f][e * arity[f] + t] + 1] += arity[f] - 1;
  i64 longest = 0;
  for (i64 v = 0; v < nv; ++v) {
    if (fill[v + 1] > longest) longest = fill[v + 1];
    fill[v + 1] += fill[v];
  }
  for (i64 v = 0; v < nv; ++v) dest[fill[v]] = NULL, brows[fill[v]++] = (i32)v;
  for (i64 f = 0; f < n_factors; ++f) {
    const i64 a = arity[f], mf = m[f];
    const i64* edges = ids[f];
    for (i64 e = 0; e < mf; ++e)
      for (i64 t = 0; t < a; ++t) {
        i64 v = edges[e * a + t];
        for (i64 s = 0; s < a; ++s)
          if (s != t) dest[fill[v]] = blocks[f] + (t * mf + e) * a + s, brows[fill[v]++] = (i32)edges[e * a + s];
      }
  }
  i64* distinct = malloc(sizeof(i64) * (size_t)(longest > 0 ? longest : 1));
  if (!distinct) {
    free(fill), free(dest);
    return -1;
  }
  /* fill[v] is now the end of column v's candidates, fill[v - 1] (0 for v = 0) their start. */
  i64 nb = 0, start = 0;
  for (i64 v = 0; v < nv; ++v) {
    i64 end = fill[v], count = 0;
    for (i64 i = start; i < end; ++i)
      if (mark[brows[i]] != v) mark[brows[i]] = v, distinct[count++] = brows[i];
    sort(distinct, count);
    for (i64 k = 0; k < count; ++k) where[distinct[k]] = nb + k;
    diagonal[v] = where[v];
    for (i64 i = start; i < end; ++i)
      if (dest[i]) *dest[i] = (i32)where[brows[i]];
    bptr[v] = (i32)nb;
    for (i64 k = 0; k < count; ++k) brows[nb++] = (i32)distinct[k]; /* behind what is left to read: nb <= start */
    start = end;
  }
  bptr[nv] = (i32)nb;
  for (i64 f = 0; f < n_factors; ++f)
    for (i64 e = 0; e < m[f]; ++e)
      for (i64 t = 0; t < arity[f]; ++t)
        blocks[f][(t * m[f] + e) * arity[f] + t] = (i32)diagonal[ids[f][e * arity[f] + t]];
  free(distinct);
  free(dest);
  free(fill);
  return nb;
}

/* The layout of H.data: L (nv), base (nv + 1) and within (nb). Returns nnz = base[nv]. */
static i64 layout(i64 nv, const i64* dims, const i32* bptr, const i32* brows, i64* L, i64* base, i32* within) {
  base[0] = 0;
  for (i64 v = 0; v < nv; ++v) {
    i64 length = 0;
    for (i64 k = bptr[v]; k < bptr[v + 1]; ++k) {
      within[k] = (i32)length;
      length += dims[brows[k]];
    }
    L[v] = length;
    base[v + 1] = base[v] + length * dims[v];
  }
  return base[nv];
}

/* H's scalar CSC pattern from the blocks and the layout: indptr (n + 1), indices (nnz) and the
 * position of every diagonal entry (n). Each column of v lists the rows of v's blocks in order:
 * the first one is written, the others (the same rows) copied from it. */
static void expand_pattern(i64 nv, const i64* dims, const i64* offsets, const i32* bptr, const i32* brows,
                           const i64* L, const i64* base, i32* indptr, i32* indices, i32* diagonal) {
  for (i64 v = 0; v < nv; ++v) {
    i64 at = base[v], diagonal_at = 0;
    i32* first = indices + at;
    for (i64 k = bptr[v]; k < bptr[v + 1]; ++k) {
      i64 w = brows[k];
      if (w == v) diagonal_at = at;
      for (i64 i = 0; i < dims[w]; ++i) indices[at++] = (i32)(offsets[w] + i);
    }
    for (i64 j = 0; j < dims[v]; ++j) {
      indptr[offsets[v] + j] = (i32)(base[v] + j * L[v]);
      diagonal[offsets[v] + j] = (i32)(diagonal_at + j * L[v] + j);
      if (j) memcpy(first + j * L[v], first, sizeof(i32) * (size_t)L[v]);
    }
  }
  indptr[offsets[nv]] = (i32)base[nv];
}

/* One factor type's scatters: where entry [p, q] of every edge's A_e^T A_e goes in H.data (m W^2,
 * row p in slot t at coordinate j of its variable b: column o_b + j, which starts at
 * base_b + j L_b; column q in slot s at coordinate i: row i of block[t, e, s] in it) and the
 * coordinate of every column of A_e (m W). With d > 0 every slot has dimension d, a constant where
 * factor_scatter calls it, so that the short loops over coordinates unroll (CSAIL, d = 3: 34 -> 25-31
 * us). */
static inline __attribute__((always_inline)) void scatter_edges(i64 m, i64 arity, const i64* slot_dims, i64 d,
                                                                const i64* ids, const i32* blocks,
                                                                const i64* offsets, const i64* L, const i64* base,
                                                                const i32* within, i32* positions, i32* columns) {
  i64 width = 0;
  for (i64 s = 0; s < arity; ++s) width += d ? d : slot_dims[s];
  for (i64 e = 0; e < m; ++e) {
    const i64* edge = ids + e * arity;
    i32* column = columns + e * width;
    for (i64 s = 0; s < arity; ++s)
      for (i64 i = 0, ds = d ? d : slot_dims[s]; i < ds; ++i) *column++ = (i32)(offsets[edge[s]] + i);
    i32* out = positions + e * width * width;
    for (i64 t = 0; t < arity; ++t) {
      i64 b = edge[t];
      const i32* block = blocks + (t * m + e) * arity;
      for (i64 j = 0, dt = d ? d : slot_dims[t]; j < dt; ++j) {
        i64 row = base[b] + j * L[b];
        for (i64 s = 0; s < arity; ++s) {
          i64 at = row + within[block[s]];
          for (i64 i = 0, ds = d ? d : slot_dims[s]; i < ds; ++i) *out++ = (i32)(at + i);
        }
      }
    }
  }
}

/* Slots of any dimensions, in a function of its own: inlined into factor_scatter with d = 0, the
 * loops ran 1.4x slower on sphere2500's (d = 6). */
static __attribute__((noinline)) void scatter_any(i64 m, i64 arity, const i64* slot_dims, const i64* ids,
                                                  const i32* blocks, const i64* offsets, const i64* L,
                                                  const i64* base, const i32* within, i32* positions, i32* columns) {
  scatter_edges(m, arity, slot_dims, 0, ids, blocks, offsets, L, base, within, positions, columns);
}

static void factor_scatter(i64 m, i64 arity, const i64* slot_dims, const i64* ids, const i32* blocks,
                           const i64* offsets, const i64* L, const i64* base, const i32* within, i32* positions,
                           i32* columns) {
  i64 d = slot_dims[0];
  for (i64 s = 1; s < arity; ++s)
    if (slot_dims[s] != d) d = 0;
#define SCATTER(D) scatter_edges(m, arity, slot_dims, D, ids, blocks, offsets, L, base, within, positions, columns)
  switch (d) { /* SO(2), SE(2) and SO(3); unrolled for d = 6 (SE(3)), the loops measured 1.3x slower */
    case 1: SCATTER(1); break;
    case 2: SCATTER(2); break;
    case 3: SCATTER(3); break;
    default: scatter_any(m, arity, slot_dims, ids, blocks, offsets, L, base, within, positions, columns);
  }
#undef SCATTER
}

/* Whether every edge names variables in range, none twice, each of its slot's dimension (the
 * checks of _factors.check_edges, in one pass): 0, or -3 and the first failing factor in *failed. */
static int check_edges(i64 nv, i64 n_factors, const i64* dims, const i64* m, const i64* arity, const i64* slot_dims,
                       const i64* const* ids, i64* failed) {
  for (i64 f = 0; f < n_factors; slot_dims += arity[f], ++f)
    for (i64 e = 0; e < m[f]; ++e) {
      const i64* edge = ids[f] + e * arity[f];
      for (i64 s = 0; s < arity[f]; ++s) {
        int bad = edge[s] < 0 || edge[s] >= nv || dims[edge[s]] != slot_dims[s];
        for (i64 t = 0; t < s && !bad; ++t) bad = edge[t] == edge[s];
        if (bad) {
          *failed = f;
          return -3;
        }
      }
    }
  return 0;
}

/* A structure's arrays in one pass (_patterns.StructureBuild): the edges checked, then the
 * variables' offsets (offsets: nv + 1), the block pattern, H's pattern and every factor type's
 * scatters, into the caller's arrays: bptr (nv + 1), brows (room: nv + sum_f m_f a_f (a_f - 1)),
 * indptr (n + 1), indices (room: nnz_room), diagonal (n), and per factor type positions (m W^2)
 * and columns (m W), its slot_dims after the previous one's. Writes sizes = (nb, nnz). Returns 0,
 * -1 without memory, -2 where H holds more than nnz_room entries, -3 where an edge fails the checks
 * (sizes[0]: its factor type). */
static int build(i64 nv, i64 n_factors, const i64* dims, i64* offsets, const i64* m, const i64* arity,
                 const i64* slot_dims, const i64* const* ids, i32* bptr, i32* brows, i32* indptr, i32* indices,
                 i64 nnz_room, i32* diagonal, i32* const* positions, i32* const* columns, i64* sizes) {
  if (check_edges(nv, n_factors, dims, m, arity, slot_dims, ids, sizes)) return -3;
  offsets[0] = 0;
  for (i64 v = 0; v < nv; ++v) offsets[v + 1] = offsets[v] + dims[v];
  i64 pairs = 0; /* every edge's blocks, factor after factor */
  for (i64 f = 0; f < n_factors; ++f) pairs += m[f] * arity[f] * arity[f];
  i32* block_of = malloc(sizeof(i32) * (size_t)(pairs > 0 ? pairs : 1));
  i32** blocks = malloc(sizeof(i32*) * (size_t)n_factors);
  i64* L = malloc(sizeof(i64) * (size_t)(2 * nv + 1)); /* then base: nv + 1 */
  i32* within = malloc(sizeof(i32) * (size_t)(nv + pairs)); /* nb <= nv + pairs */
  int status = -1;
  if (!block_of || !blocks || !L || !within) goto done;
  for (i64 f = 0, at = 0; f < n_factors; at += m[f] * arity[f] * arity[f], ++f) blocks[f] = block_of + at;
  i64 nb = block_pattern(nv, n_factors, m, arity, ids, bptr, brows, blocks);
  if (nb < 0) goto done;
  i64 *base = L + nv, nnz = layout(nv, dims, bptr, brows, L, base, within);
  sizes[0] = nb, sizes[1] = nnz, status = -2;
  if (nnz > nnz_room) goto done;
  expand_pattern(nv, dims, offsets, bptr, brows, L, base, indptr, indices, diagonal);
  for (i64 f = 0; f < n_factors; slot_dims += arity[f], ++f)
    factor_scatter(m[f], arity[f], slot_dims, ids[f], blocks[f], offsets, L, base, within, positions[f], columns[f]);
  status = 0;
done:
  free(block_of), free(blocks), free(L), free(within);
  return status;
}

/* build with its arguments packed in one array, addresses as integers, in its order (as
 * _patterns.StructureBuild writes them): one argument to pass, from Python or to the worker
 * (early_start). */
#define ARG(i, type) ((type)(intptr_t)args[i])
int build_structure(const i64* args) {
  return build(args[0], args[1], ARG(2, const i64*), ARG(3, i64*), ARG(4, const i64*), ARG(5, const i64*),
               ARG(6, const i64*), ARG(7, const i64* const*), ARG(8, i32*), ARG(9, i32*), ARG(10, i32*),
               ARG(11, i32*), args[12], ARG(13, i32*), ARG(14, i32* const*), ARG(15, i32* const*), ARG(16, i64*));
}
#undef ARG

/* The lower (upper != 0: the upper) triangle of B = P H P^T, P putting variable order[c] c-th with
 * its coordinates in order, as CSC (indptr: n + 1, rows: (nnz + n) / 2, sorted) and the position in
 * H.data of each entry (gather). Column (c, j) of B (variable v = order[c], coordinate j) holds
 * the rows i >= j of v's diagonal block, then the off-diagonal blocks below it in B's order (the
 * upper triangle: the blocks above, then the rows i <= j); size: the room in rows and gather. Also
 * writes P as H's coordinate of each of B's (perm: n). Returns 0, -1 without memory, -2 where the
 * blocks would write past size (they do not make H's pattern). */
int permuted_triangle(i64 nv, const i64* dims, const i32* h_indptr, const i32* bptr, const i32* brows,
                      const i64* order, int upper, i64 size, i32* indptr, i32* rows, i32* gather, i64* perm) {
  i64 nb = bptr[nv];
  i64* rank = malloc(sizeof(i64) * (size_t)(3 * nv + 4 * nb + 2));
  if (!rank) return -1;
  i64* new_offsets = rank + nv;      /* nv + 1 */
  i64* keys = new_offsets + nv + 1;  /* one column's off-diagonal blocks: rank * nb + k, sorted; then s_k */
  i64* start = keys + nb;            /* s_k: where block k's entry (o_w, o_v) sits in H.data */
  i64* offsets = start + nb;         /* o_v */
  i64* first_row = offsets + nv;     /* per sorted block: its first row in B */
  i64* height = first_row + nb;      /* and its rows */
  for (i64 c = 0; c < nv; ++c) rank[order[c]] = c;
  new_offsets[0] = 0;
  for (i64 c = 0; c < nv; ++c) new_offsets[c + 1] = new_offsets[c] + dims[order[c]];
  i64 offset = 0;
  for (i64 v = 0; v < nv; ++v) {
    i64 first = h_indptr[offset], down = 0;
    for (i64 k = bptr[v]; k < bptr[v + 1]; ++k) {
      start[k] = first + down;
      down += dims[brows[k]];
    }
    offsets[v] = offset;
    offset += dims[v];
  }
  for (i64 c = 0; c < nv; ++c)
    for (i64 i = 0; i < dims[order[c]]; ++i) perm[new_offsets[c] + i] = offsets[order[c]] + i;
  i64 at = 0, column = 0;
  for (i64 c = 0; c < nv; ++c) {
    i64 v = order[c], d = dims[v], length = 0, count = 0, diagonal = -1;
    for (i64 k = bptr[v]; k < bptr[v + 1]; ++k) {
      i64 r = rank[brows[k]];
      length += dims[brows[k]];
      if (r == c) diagonal = k;
      else if (upper ? r < c : r > c) keys[count++] = r * nb + k;
    }
    sort(keys, count);
    i64 stream = 0;
    for (i64 x = 0; x < count; ++x) { /* decoded once for the d columns (a division each) */
      i64 k = keys[x] % nb, r = keys[x] / nb;
      first_row[x] = new_offsets[r], height[x] = dims[brows[k]], keys[x] = start[k];
      stream += height[x];
    }
    if (diagonal < 0 || at + d * stream + d * (d + 1) / 2 > size) { /* not the blocks of H's pattern */
      free(rank);
      return -2;
    }
    for (i64 j = 0; j < d; ++j, ++column) {
      i64 step = j * length; /* from coordinate 0 to j in H's columns of v */
      indptr[column] = (i32)at;
      if (!upper)
        for (i64 i = j; i < d; ++i, ++at) rows[at] = (i32)(new_offsets[c] + i), gather[at] = (i32)(start[diagonal] + step + i);
      for (i64 x = 0; x < count; ++x)
        for (i64 i = 0; i < height[x]; ++i, ++at)
          rows[at] = (i32)(first_row[x] + i), gather[at] = (i32)(keys[x] + step + i);
      if (upper)
        for (i64 i = 0; i <= j; ++i, ++at) rows[at] = (i32)(new_offsets[c] + i), gather[at] = (i32)(start[diagonal] + step + i);
    }
  }
  indptr[column] = (i32)at;
  free(rank);
  return 0;
}

/* CHOLMOD's supernodal symbolic factor of B from the variables' one: supernode k of the variables'
 * graph (variables super_b[k] ... super_b[k + 1] - 1 of B's order, block rows s_b[pi_b[k] ...
 * pi_b[k + 1] - 1]) becomes the supernode of their coordinates, with the coordinates of its block
 * rows as its rows. The blocks are dense, so each coordinate's column holds what its variable's
 * does (below the diagonal). Writes super, pi, px (nsuper + 1), s (the rows) and colcount (n: the
 * rows of each column from its diagonal down, as CHOLMOD keeps them), and sizes = (xsize,
 * maxcsize, maxesize) as cholmod_super_symbolic defines them. Returns 0; -1 without memory or
 * where an index passes 32 bits (CHOLMOD's int version). */
int expand_supernodes(i64 nsuper, const i64* dims, const i32* super_b, const i32* pi_b, const i32* s_b, i32* super,
                      i32* pi, i32* px, i32* s, i32* colcount, i64* sizes) {
  i64 nv = super_b[nsuper];
  i64* offsets = malloc(sizeof(i64) * (size_t)(nv + 1));
  if (!offsets) return -1;
  offsets[0] = 0;
  for (i64 c = 0; c < nv; ++c) offsets[c + 1] = offsets[c] + dims[c];
  i64 n = offsets[nv];
  i64* supermap = malloc(sizeof(i64) * (size_t)(n > 0 ? n : 1));
  if (!supermap) {
    free(offsets);
    return -1;
  }
  i64 rows = 0, entries = 0, maxcsize = 1, maxesize = 1;
  for (i64 k = 0; k < nsuper; ++k) {
    super[k] = (i32)offsets[super_b[k]];
    pi[k] = (i32)rows;
    px[k] = (i32)entries;
    for (i64 p = pi_b[k]; p < pi_b[k + 1]; ++p) {
      i64 w = s_b[p];
      for (i64 i = 0; i < dims[w]; ++i) s[rows++] = (i32)(offsets[w] + i);
    }
    i64 first = offsets[super_b[k]], last = offsets[super_b[k + 1]], nscol = last - first, nsrow = rows - pi[k];
    for (i64 j = first; j < last; ++j) supermap[j] = k, colcount[j] = (i32)(nsrow - (j - first));
    entries += nscol * nsrow;
    if (entries > INT32_MAX || rows > INT32_MAX) {
      free(supermap), free(offsets);
      return -1;
    }
  }
  super[nsuper] = (i32)n, pi[nsuper] = (i32)rows, px[nsuper] = (i32)entries;
  /* The largest update of a supernode to an ancestor (C: ndrow2 x ndrow1) and the largest part below
   * a supernode's diagonal (E), as cholmod_super_symbolic2 computes them. */
  for (i64 d = 0; d < nsuper; ++d) {
    i64 nscol = super[d + 1] - super[d], p = pi[d] + nscol, plast = p, pend = pi[d + 1];
    if (pend - p > maxesize) maxesize = pend - p;
    i64 slast = p == pend ? -1 : supermap[s[p]];
    for (; p <= pend; ++p) {
      i64 k = p == pend ? -1 : supermap[s[p]];
      if (k != slast) {
        if ((pend - plast) * (p - plast) > maxcsize) maxcsize = (pend - plast) * (p - plast);
        plast = p, slast = k;
      }
    }
  }
  sizes[0] = entries, sizes[1] = maxcsize, sizes[2] = maxesize;
  free(supermap), free(offsets);
  return 0;
}

/* The variables' simplicial symbolic factorization in a fill-reducing order, for a factor whose
 * column counts CHOLMOD then expands (Cholmod._expand): the elimination tree of B's block pattern
 * in `order` (Liu's algorithm with path compression), a postorder of it (children in increasing
 * order, by an iterative depth-first search), and the count of blocks in each column of L, its
 * diagonal block included, by the row subtrees (row k of L holds the nodes on the tree paths from
 * the rows of column k up to k). Writes variables (nv: the postordered order, variables[j] the
 * j-th) and counts (nv, in that order). With weights (the variables' dimensions, or NULL: 1 each),
 * each block counts its rows' weight: the rows of each column of L in coordinates. The row
 * subtrees take nnz(L) steps: past `budget` the factor fills in too much for a simplicial one, and
 * the caller asks CHOLMOD instead. Returns 0, -1 without memory, -2 past the budget. */
int block_symbolic(i64 nv, const i32* bptr, const i32* brows, const i64* order, i64 budget, i64* variables,
                   i64* counts, const i64* weights) {
  i64* work = malloc(sizeof(i64) * (size_t)(6 * nv + 1));
  if (!work) return -1;
  i64 *rank = work, *parent = work + nv, *ancestor = work + 2 * nv, *mark = work + 3 * nv;
  i64 *head = work + 4 * nv, *next = work + 5 * nv; /* children lists, then the search's stack */
  for (i64 k = 0; k < nv; ++k) rank[order[k]] = k;
  for (i64 k = 0; k < nv; ++k) { /* etree: column k's rows i < k, walked up to their roots */
    parent[k] = ancestor[k] = -1;
    i64 v = order[k];
    for (i64 p = bptr[v]; p < bptr[v + 1]; ++p)
      for (i64 i = rank[brows[p]]; i != -1 && i < k;) {
        i64 up = ancestor[i];
        ancestor[i] = k;
        if (up == -1) parent[i] = k;
        i = up;
      }
  }
  i64 steps = 0;
  for (i64 k = 0; k < nv; ++k) { /* row subtrees: counts in the order before the postorder */
    mark[k] = k;
    counts[k] = 0;
  }
  for (i64 k = 0; k < nv; ++k) {
    i64 v = order[k], w = weights ? weights[v] : 1; /* row k's blocks: its variable's rows each */
    counts[k] += w;
    for (i64 p = bptr[v]; p < bptr[v + 1]; ++p)
      for (i64 j = rank[brows[p]]; j != -1 && j < k && mark[j] != k; j = parent[j]) {
        mark[j] = k;
        counts[j] += w;
        if (++steps > budget) {
          free(work);
          return -2;
        }
      }
  }
  for (i64 k = 0; k < nv; ++k) head[k] = -1;
  for (i64 k = nv - 1; k >= 0; --k) /* pushed in decreasing order: each list increasing */
    if (parent[k] != -1) next[k] = head[parent[k]], head[parent[k]] = k;
  i64* stack = ancestor; /* done with it */
  i64 j = 0;
  for (i64 root = 0; root < nv; ++root) {
    if (parent[root] != -1) continue;
    i64 top = 0;
    stack[0] = root;
    while (top >= 0) {
      i64 node = stack[top], child = head[node];
      if (child == -1) { /* every child done: the node is next */
        --top;
        mark[j++] = node;
      } else {
        head[node] = next[child];
        stack[++top] = child;
      }
    }
  }
  for (i64 q = 0; q < nv; ++q) rank[q] = counts[mark[q]]; /* counts in the postorder (rank reused) */
  for (i64 q = 0; q < nv; ++q) variables[q] = order[mark[q]], counts[q] = rank[q];
  free(work);
  return 0;
}
