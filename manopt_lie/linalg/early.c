/* A new structure's build and analysis on a worker thread (_early.py, _patterns.Plan), compiled
 * with patterns.c into one library (_patterns._library), whose functions it calls. */
#include <pthread.h>
#include <stdint.h>
#include <stdlib.h>
#include <string.h>

typedef int64_t i64;
typedef int32_t i32;

/* patterns.c's */
int build_structure(const i64* args);
int permuted_triangle(i64 nv, const i64* dims, const i32* h_indptr, const i32* bptr, const i32* brows,
                      const i64* order, int upper, i64 size, i32* indptr, i32* rows, i32* gather, i64* perm);
int block_symbolic(i64 nv, const i32* bptr, const i32* brows, const i64* order, i64 budget, i64* variables,
                   i64* counts, const i64* weights);

/* A new structure's analysis on a worker thread (_early.py), after its build where it is given one
 * (build: build_structure's packed arguments, whose outputs the analysis then reads; NULL where
 * the caller built it): AMD's order of the variables' graph
 * (amd: AMD's amd_order, called through its address), the variables' simplicial symbolic
 * factorization in that order (block_symbolic, up to fill blocks of L per block of H), and, where CHOLMOD's default choice of kind is
 * simplicial (fl < supernodal_switch lnz, the coordinates' costs from the blocks' as in
 * Cholmod._analyze_blocks, every variable of dimension d), B's simplicial symbolic factor: its cost
 * (lnz, fl), its column counts (colcount: n) and the upper triangle of B in the postordered order
 * (permuted_triangle, size > 0). Each step runs where the one before succeeded;
 * status: AMD's, block_symbolic's, permuted_triangle's (NOT_RUN: not run). Every array is the
 * caller's, kept alive until early_join.
 *
 * One worker thread per process runs the analyses in the order they were started: made at the
 * first, it sleeps between them (a thread made per analysis cost its caller 0.06-0.15 ms). A forked
 * child has no worker and makes its own; the analyses its parent had started are not its to wait
 * for (early_join says so). */
#define NOT_RUN 2 /* a status none of the steps returns */
typedef int (*amd_order_fn)(i32 n, const i32* Ap, const i32* Ai, i32* P, double* Control, double* Info);

typedef struct early_analysis {
  struct early_analysis* next; /* in the worker's queue */
  unsigned long forks; /* early_forks where it started */
  int done;
  amd_order_fn amd;
  i64 nv, d, fill, size;
  double supernodal_switch;
  const i64* dims;
  const i32 *h_indptr, *bptr, *brows;
  i32* amd_order;
  i64 *order, *variables, *counts, *perm;
  i32 *indptr, *rows, *gather, *colcount;
  double* cost;
  i64 status[3];
  const i64* build; /* build_structure's packed arguments, or NULL */
  int taken;        /* the build taken by the worker or by early_built's caller, or none to do */
  int built;        /* the build done, or none to do */
  i64 build_status;
} early_analysis;

static pthread_mutex_t early_lock = PTHREAD_MUTEX_INITIALIZER;
static pthread_cond_t early_queued = PTHREAD_COND_INITIALIZER, early_done = PTHREAD_COND_INITIALIZER;

/* The build, by whichever thread took it (under the lock); done, it tells the others. */
static void early_build(early_analysis* a) {
  int status = build_structure(a->build);
  pthread_mutex_lock(&early_lock);
  a->build_status = status, a->built = 1;
  pthread_cond_broadcast(&early_done);
  pthread_mutex_unlock(&early_lock);
}

/* The analysis, after the build (build: this thread took it; else waited for where another did). */
static void early_run(early_analysis* a, int build) {
  if (build) {
    early_build(a);
  } else if (a->build) {
    pthread_mutex_lock(&early_lock);
    while (!a->built) pthread_cond_wait(&early_done, &early_lock);
    pthread_mutex_unlock(&early_lock);
  }
  if (a->build_status != 0) return;
  i64 nv = a->nv, d = a->d;
  a->status[0] = a->amd((i32)nv, a->bptr, a->brows, a->amd_order, NULL, NULL);
  if (a->status[0] != 0 && a->status[0] != 1) return; /* AMD_OK, AMD_OK_BUT_JUMBLED */
  for (i64 k = 0; k < nv; ++k) a->order[k] = a->amd_order[k];
  i64 budget = a->fill * a->bptr[nv]; /* per block: the build's brows are its room, the nb blocks first */
  a->status[1] = block_symbolic(nv, a->bptr, a->brows, a->order, budget, a->variables, a->counts, NULL);
  if (a->status[1] != 0 || a->size <= 0) return;
  double lnz_b = 0, fl_b = 0; /* sum c and sum c^2 over the variables, then over the coordinates */
  for (i64 k = 0; k < nv; ++k) lnz_b += (double)a->counts[k], fl_b += (double)a->counts[k] * (double)a->counts[k];
  double lnz = (double)(d * d) * lnz_b - (double)(nv * d * (d - 1)) / 2;
  double fl = (double)(d * d * d) * fl_b - (double)(d * d * (d - 1)) * lnz_b + (double)(nv * (d - 1) * d * (2 * d - 1)) / 6;
  if (fl >= a->supernodal_switch * lnz) return; /* supernodal: its triangle is the lower one, in another order */
  a->cost[0] = lnz, a->cost[1] = fl;
  for (i64 c = 0; c < nv; ++c) /* column j of variable c's d holds d counts[c] - j rows (Cholmod._expand) */
    for (i64 j = 0; j < d; ++j) a->colcount[c * d + j] = (i32)(d * a->counts[c] - j);
  a->status[2] = permuted_triangle(nv, a->dims, a->h_indptr, a->bptr, a->brows, a->variables, 1, a->size, a->indptr,
                                   a->rows, a->gather, a->perm);
}

static early_analysis *early_head = NULL, *early_tail = NULL;
static int early_running = 0;           /* a worker runs in this process */
static unsigned long early_forks = 0;   /* forks from the first process to this one */

static void early_forked(void) { /* pthread_atfork's child: no worker, nothing queued, the lock as new */
  pthread_mutex_t unlocked = PTHREAD_MUTEX_INITIALIZER;
  pthread_cond_t fresh = PTHREAD_COND_INITIALIZER;
  early_lock = unlocked, early_queued = fresh, early_done = fresh;
  early_head = early_tail = NULL, early_running = 0, ++early_forks;
}

static void* early_work(void* unused) {
  (void)unused;
  pthread_mutex_lock(&early_lock);
  for (;;) {
    while (!early_head) pthread_cond_wait(&early_queued, &early_lock);
    early_analysis* a = early_head;
    early_head = a->next;
    if (!early_head) early_tail = NULL;
    int build = !a->taken;
    a->taken = 1;
    pthread_mutex_unlock(&early_lock);
    early_run(a, build);
    pthread_mutex_lock(&early_lock);
    a->done = 1;
    pthread_cond_broadcast(&early_done);
  }
  return NULL;
}

static int early_worker(void) { /* with the lock held: whether a worker runs, made if need be */
  static int watched = 0; /* the fork handler registered */
  if (early_running) return 1;
  if (!watched) watched = pthread_atfork(NULL, NULL, early_forked) == 0;
  pthread_attr_t attributes;
  pthread_t worker;
  if (!watched || pthread_attr_init(&attributes) != 0) return 0;
  early_running = pthread_attr_setdetachstate(&attributes, PTHREAD_CREATE_DETACHED) == 0 &&
                  pthread_create(&worker, &attributes, early_work, NULL) == 0;
  pthread_attr_destroy(&attributes);
  return early_running;
}

/* Starts the analysis, after the build if one is given (on the caller's thread where no worker can
 * be made), and returns its handle, for early_built and early_join; NULL without memory. Its
 * arguments are packed in args, addresses as integers, as _early.EarlyAnalysis writes them: amd,
 * nv, d, dims, h_indptr, bptr, brows, fill, size, then the outputs amd_order, order, variables,
 * counts, indptr, rows, gather, perm, colcount and cost. */
#define ARG(i, type) ((type)(intptr_t)args[i])
void* early_start(const i64* build, const i64* args, double supernodal_switch) {
  early_analysis* a = malloc(sizeof(early_analysis));
  if (!a) return NULL;
  a->next = NULL, a->done = 0;
  a->build = build, a->taken = a->built = build == NULL, a->build_status = 0;
  a->amd = ARG(0, amd_order_fn);
  a->nv = args[1], a->d = args[2], a->fill = args[7], a->size = args[8], a->supernodal_switch = supernodal_switch;
  a->dims = ARG(3, const i64*), a->h_indptr = ARG(4, const i32*), a->bptr = ARG(5, const i32*);
  a->brows = ARG(6, const i32*), a->amd_order = ARG(9, i32*), a->order = ARG(10, i64*);
  a->variables = ARG(11, i64*), a->counts = ARG(12, i64*), a->indptr = ARG(13, i32*), a->rows = ARG(14, i32*);
  a->gather = ARG(15, i32*), a->perm = ARG(16, i64*), a->colcount = ARG(17, i32*), a->cost = ARG(18, double*);
#undef ARG
  a->status[0] = a->status[1] = a->status[2] = NOT_RUN;
  pthread_mutex_lock(&early_lock);
  a->forks = early_forks;
  int queued = early_worker();
  if (queued) {
    if (early_tail) early_tail->next = a;
    else early_head = a;
    early_tail = a;
  }
  pthread_mutex_unlock(&early_lock);
  if (queued) /* after the unlock: the worker woken does not block on the lock (CSAIL: 0.015 -> 0.01 ms) */
    pthread_cond_signal(&early_queued);
  else
    early_run(a, !a->taken), a->done = 1;
  return a;
}

/* The analysis's build, done, its status written (build_structure's): made here where the worker
 * has not taken it yet (it woke late: on a VM an idle vCPU may take 0.1 ms or more), else waited
 * for. Returns 0; -1 in a process forked from the one that started it (as early_join). */
int early_built(void* handle, i64* status) {
  early_analysis* a = handle;
  pthread_mutex_lock(&early_lock);
  int ours = a->forks == early_forks, build = ours && !a->taken;
  a->taken |= build;
  while (ours && !build && !a->built) pthread_cond_wait(&early_done, &early_lock);
  pthread_mutex_unlock(&early_lock);
  if (build) early_build(a);
  *status = a->build_status;
  return ours ? 0 : -1;
}

/* Waits for the analysis, writes its status (3) and frees the handle. Returns 0; -1 in a process
 * forked from the one that started it (its worker did not come along: the arrays are not to be
 * read). */
int early_join(void* handle, i64* status) {
  early_analysis* a = handle;
  pthread_mutex_lock(&early_lock);
  if (a->forks != early_forks) { /* started by the parent */
    pthread_mutex_unlock(&early_lock);
    free(a);
    return -1;
  }
  while (!a->done) pthread_cond_wait(&early_done, &early_lock);
  pthread_mutex_unlock(&early_lock);
  memcpy(status, a->status, sizeof(a->status));
  free(a);
  return 0;
}

/* A structure's build and its analysis planned in the caller's two buffers and, where asked, started
 * (_patterns.StructureBuild, _early.EarlyAnalysis): every array cut from the buffers, the arguments
 * of build_structure and early_start packed there, and, first in buf64, a table of where each array
 * starts (PLAN_* entries, then each factor type's positions and columns: the caller makes its views
 * from it when it reads them). head (int64; HEAD_* below, then per factor type its edges' address,
 * and its m, arity and slot dimensions, which the build reads there) gives the sizes, the flags
 * (PLAN_BUILD: the build's arrays and arguments; PLAN_ANALYSIS: the analysis's, of H's entries
 * bounded by room; PLAN_START: start it, after the build where one is planned), the arrays the
 * caller keeps apart (dims; H's indptr and indices, which SciPy takes as they are; the block pattern
 * where the caller built it), the buffers and their lengths, AMD's address and the fill budget.
 * Returns the analysis's handle where started; 0 where none is; -1 where the buffers are not as long
 * as the plan (the caller sizes them as it does); -2 without memory to start. */
enum { HEAD_NV, HEAD_K, HEAD_N, HEAD_ROOM, HEAD_FLAGS, HEAD_D, HEAD_DIMS, HEAD_INDPTR, HEAD_INDICES, HEAD_BPTR,
       HEAD_BROWS, HEAD_BUF64, HEAD_LEN64, HEAD_BUF32, HEAD_LEN32, HEAD_AMD, HEAD_FILL, HEAD_FACTORS };
enum { PLAN_BUILD = 1, PLAN_ANALYSIS = 2, PLAN_START = 4 };
enum { PLAN_BUILD_ARGS, PLAN_EARLY_ARGS, PLAN_SIZES, PLAN_OFFSETS, PLAN_ORDER, PLAN_VARIABLES, PLAN_COUNTS,
       PLAN_PERM, PLAN_STATUS, PLAN_COST, PLAN_BUILD_STATUS, PLAN_BPTR, PLAN_CANDIDATES, PLAN_DIAGONAL,
       PLAN_AMD_ORDER, PLAN_COLCOUNT, PLAN_TRI_INDPTR, PLAN_TRI_ROWS, PLAN_TRI_GATHER, PLAN_TRI_SIZE, PLAN_TABLE };
#define AT(i) ((i64)(intptr_t)(i))
i64 plan_structure(const i64* head, double supernodal_switch) {
  i64 nv = head[HEAD_NV], k = head[HEAD_K], n = head[HEAD_N], room = head[HEAD_ROOM], flags = head[HEAD_FLAGS];
  i64 *buf64 = (i64*)(intptr_t)head[HEAD_BUF64], *table = buf64;
  i32* buf32 = (i32*)(intptr_t)head[HEAD_BUF32];
  const i64 *ids = head + HEAD_FACTORS, *m = ids + k, *arity = m + k, *slot_dims = arity + k;
  i64 at64 = PLAN_TABLE + 2 * k, at32 = 0;
  for (i64 t = 0; t < PLAN_TABLE + 2 * k; ++t) table[t] = -1;
  i64 bptr = head[HEAD_BPTR], brows = head[HEAD_BROWS]; /* the block pattern the analysis reads */
  if (flags & PLAN_BUILD) {
    i64 candidates = nv;
    for (i64 f = 0; f < k; ++f) candidates += m[f] * arity[f] * (arity[f] - 1);
    table[PLAN_BUILD_ARGS] = at64, at64 += 17 + 3 * k;
    table[PLAN_SIZES] = at64, at64 += 2;
    table[PLAN_OFFSETS] = at64, at64 += nv + 1;
    table[PLAN_BPTR] = at32, at32 += nv + 1;
    table[PLAN_CANDIDATES] = at32, at32 += candidates;
    table[PLAN_DIAGONAL] = at32, at32 += n;
    for (int columns = 0; columns < 2; ++columns) /* every factor type's positions (m W^2), then columns (m W) */
      for (i64 f = 0, s0 = 0; f < k; s0 += arity[f], ++f) {
        i64 w = 0;
        for (i64 s = 0; s < arity[f]; ++s) w += slot_dims[s0 + s];
        table[PLAN_TABLE + columns * k + f] = at32, at32 += m[f] * w * (columns ? 1 : w);
      }
    bptr = AT(buf32 + table[PLAN_BPTR]), brows = AT(buf32 + table[PLAN_CANDIDATES]); /* the build's */
  }
  i64 size = (room + n) / 2; /* the triangle's room: one triangle of H, its diagonal included */
  if (flags & PLAN_ANALYSIS) {
    table[PLAN_EARLY_ARGS] = at64, at64 += 19;
    table[PLAN_ORDER] = at64, at64 += nv;
    table[PLAN_VARIABLES] = at64, at64 += nv;
    table[PLAN_COUNTS] = at64, at64 += nv;
    table[PLAN_PERM] = at64, at64 += n;
    table[PLAN_STATUS] = at64, at64 += 3;
    table[PLAN_COST] = at64, at64 += 2;
    table[PLAN_BUILD_STATUS] = at64, at64 += 1;
    table[PLAN_AMD_ORDER] = at32, at32 += nv;
    table[PLAN_COLCOUNT] = at32, at32 += n;
    table[PLAN_TRI_INDPTR] = at32, at32 += n + 1;
    table[PLAN_TRI_ROWS] = at32, at32 += size;
    table[PLAN_TRI_GATHER] = at32, at32 += size;
    table[PLAN_TRI_SIZE] = size;
  }
  if (at64 != head[HEAD_LEN64] || at32 != head[HEAD_LEN32]) return -1;
  i64* build_args = NULL;
  if (flags & PLAN_BUILD) {
    i64* a = build_args = buf64 + table[PLAN_BUILD_ARGS];
    i64* pointers = a + 17; /* the edges', the positions' and the columns' addresses, k each */
    a[0] = nv, a[1] = k, a[2] = head[HEAD_DIMS], a[3] = AT(buf64 + table[PLAN_OFFSETS]), a[4] = AT(m);
    a[5] = AT(arity), a[6] = AT(slot_dims), a[7] = AT(pointers), a[8] = AT(buf32 + table[PLAN_BPTR]);
    a[9] = AT(buf32 + table[PLAN_CANDIDATES]), a[10] = head[HEAD_INDPTR], a[11] = head[HEAD_INDICES], a[12] = room;
    a[13] = AT(buf32 + table[PLAN_DIAGONAL]), a[14] = AT(pointers + k), a[15] = AT(pointers + 2 * k);
    a[16] = AT(buf64 + table[PLAN_SIZES]);
    for (i64 f = 0; f < k; ++f) {
      pointers[f] = ids[f];
      pointers[k + f] = AT(buf32 + table[PLAN_TABLE + f]);
      pointers[2 * k + f] = AT(buf32 + table[PLAN_TABLE + k + f]);
    }
  }
  if (!(flags & PLAN_ANALYSIS)) return 0;
  i64* a = buf64 + table[PLAN_EARLY_ARGS];
  a[0] = head[HEAD_AMD], a[1] = nv, a[2] = head[HEAD_D], a[3] = head[HEAD_DIMS], a[4] = head[HEAD_INDPTR];
  a[5] = bptr, a[6] = brows, a[7] = head[HEAD_FILL], a[8] = size, a[9] = AT(buf32 + table[PLAN_AMD_ORDER]);
  a[10] = AT(buf64 + table[PLAN_ORDER]), a[11] = AT(buf64 + table[PLAN_VARIABLES]);
  a[12] = AT(buf64 + table[PLAN_COUNTS]), a[13] = AT(buf32 + table[PLAN_TRI_INDPTR]);
  a[14] = AT(buf32 + table[PLAN_TRI_ROWS]), a[15] = AT(buf32 + table[PLAN_TRI_GATHER]);
  a[16] = AT(buf64 + table[PLAN_PERM]), a[17] = AT(buf32 + table[PLAN_COLCOUNT]), a[18] = AT(buf64 + table[PLAN_COST]);
  if (!(flags & PLAN_START)) return 0;
  void* handle = early_start(build_args, a, supernodal_switch);
  return handle ? AT(handle) : -2;
}
#undef AT
