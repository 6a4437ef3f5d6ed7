// Cubic B-spline prefilter (Unser; Ruijters & Thevenaz), the OpenCL twin of
// renderer/common/bspline_prefilter.cpp's float path (bsplinePrefilterMultithreaded): one
// work-item filters one line in place, neighbouring work-items on neighbouring lines whose
// samples are neighbours in memory, so every step of the recursion is one coalesced access per
// group of work-items. Mirror (whole-sample symmetric) boundaries; exact on any n >= 1.
// Also: narrow samples widened to float, and the coefficients padded with the mirror boundary.

// Pole of the cubic B-spline's inverse filter, sqrt(3) - 2.
#define BSPLINE_POLE (-0.26794919243112270f)
// The filter's DC gain (1 - z)(1 - 1/z), exactly 6; folded into the causal sweep.
#define BSPLINE_GAIN 6.0f
// Causal initialisation's truncation in float: |z|^k < FLT_EPSILON from k = 13 on
// (ceil(ln FLT_EPSILON / ln |z|) = ceil(12.1)), the C++ float horizon.
#define BSPLINE_HORIZON 13
// Anticausal initialisation's scale z / (z^2 - 1) for mirror boundaries.
#define BSPLINE_LAST_SCALE (BSPLINE_POLE / (BSPLINE_POLE * BSPLINE_POLE - 1.0f))

// The x pass's tile: TILE_LINES lines (one work-group, one work-item each) by TILE_SAMPLES
// samples of each, staged in local memory. 32 lines: a warp on NVIDIA, half a wavefront on
// AMD; 32 samples: one 128-byte transaction per line and load step.
#define TILE_LINES 32
#define TILE_SAMPLES 32
#if TILE_SAMPLES < BSPLINE_HORIZON
#error "the causal initialisation reads its first BSPLINE_HORIZON samples from the first tile"
#endif

// Index of coefficient k under mirror boundaries on an axis of n samples: mirrorIndex of
// bspline_prefilter.hpp (n == 1 gives 0).
int bspline_mirror_index(int k, int n) {
    if (n == 1) return 0;
    const int period = 2 * n - 2;
    k %= period;
    if (k < 0) k += period;
    return k < n ? k : period - k;
}

// Causal initialisation c+[0] from the line's first min(n, BSPLINE_HORIZON) samples `head`
// (n >= 2), the gain included: the sum over the mirrored signal (period 2n - 2), truncated at
// the horizon where the line is longer, exact otherwise.
float bspline_causal_init(const float *head, int n) {
    const float z = BSPLINE_POLE;
    float sum = head[0];
    float zk = z;
    if (BSPLINE_HORIZON < n) {
        for (int k = 1; k < BSPLINE_HORIZON; ++k, zk *= z) sum += zk * head[k];
        return BSPLINE_GAIN * sum;
    }
    const int period = 2 * n - 2;
    for (int k = 1; k < period; ++k, zk *= z) sum += zk * head[bspline_mirror_index(k, n)];
    return (BSPLINE_GAIN / (1.0f - pown(z, period))) * sum;
}

// Causal recursion with the gain: c+[k] = 6 s[k] + z c+[k-1].
float bspline_causal_step(float s, float previous) { return BSPLINE_GAIN * s + BSPLINE_POLE * previous; }

// Anticausal initialisation from c+[n-1] and c+[n-2].
float bspline_anticausal_init(float last, float before) {
    return BSPLINE_LAST_SCALE * (last + BSPLINE_POLE * before);
}

// Anticausal recursion c[k] = z (c[k+1] - c+[k]).
float bspline_anticausal_step(float next, float causal) { return BSPLINE_POLE * (next - causal); }

// One line per work-item (b, a), starting at b * strideB + a * strideA, its n samples
// `stride` apart; the y and z passes, where work-item b's line is b's x column: neighbouring
// work-items read neighbouring floats at every step. Two sweeps over the line (causal,
// anticausal), each reading and writing it once. The range's first dimension is rounded up to
// the work-group: work-items past countB do nothing.
__kernel void bspline_prefilter_axis(__global float *data, const uint n, const ulong stride, const ulong countB,
                                     const ulong strideB, const ulong strideA) {
    const ulong b = get_global_id(0);
    if (b >= countB || n < 2) return; // one sample: the coefficient is the sample
    __global float *line = data + b * strideB + (ulong)get_global_id(1) * strideA;
    const int len = (int)n;

    float head[BSPLINE_HORIZON];
    for (int k = 0; k < min(len, BSPLINE_HORIZON); ++k) head[k] = line[k * stride];
    float c = bspline_causal_init(head, len), before = c;
    line[0] = c;
    for (int k = 1; k < len; ++k) {
        before = c;
        c = bspline_causal_step(line[k * stride], c);
        line[k * stride] = c;
    }
    c = bspline_anticausal_init(c, before);
    line[(len - 1) * stride] = c;
    for (int k = len - 2; k >= 0; --k) {
        c = bspline_anticausal_step(c, line[k * stride]);
        line[k * stride] = c;
    }
}

// Copies samples x0 .. x0 + width - 1 of the group's TILE_LINES rows (row r at data + r * n)
// into tile[sample][line], or back: work-item `lane` moves sample x0 + lane of every row, so a
// group's access to one row is TILE_SAMPLES neighbouring floats. The tile's rows are padded by
// one float so that the transposed accesses fall in distinct local-memory banks.
void bspline_tile_load(__local float tile[TILE_SAMPLES][TILE_LINES + 1], __global const float *data, uint n,
                       ulong rows, ulong groupRow, int x0, int width, int lane) {
    for (int i = 0; i < TILE_LINES; ++i)
        if (lane < width && groupRow + i < rows) tile[lane][i] = data[(groupRow + i) * n + (ulong)(x0 + lane)];
}
void bspline_tile_store(__local float tile[TILE_SAMPLES][TILE_LINES + 1], __global float *data, uint n, ulong rows,
                        ulong groupRow, int x0, int width, int lane) {
    for (int i = 0; i < TILE_LINES; ++i)
        if (lane < width && groupRow + i < rows) data[(groupRow + i) * n + (ulong)(x0 + lane)] = tile[lane][i];
}

// The x pass: `rows` contiguous lines of n samples each (row r at data + r * n), TILE_LINES per
// work-group starting at firstRow. One work-item per line would put neighbouring work-items n
// floats apart (one memory transaction per work-item and step on a GPU); here the group moves
// its lines through local memory a tile at a time, reading and writing whole 128-byte runs,
// and each work-item runs its line's recursion on the tile (Ruijters & Thevenaz's transposed
// access, without a second buffer or extra passes). Causal sweep from the left, tile by tile;
// the last tile turns round in local memory; anticausal sweep back over the others. Out-of-range
// work-items of the last group take part in the loads (for the barriers) and store nothing.
__kernel __attribute__((reqd_work_group_size(TILE_LINES, 1, 1))) void bspline_prefilter_rows(
    __global float *data, const uint n, const ulong rows, const ulong firstRow) {
    __local float tile[TILE_SAMPLES][TILE_LINES + 1];
    const int lane = (int)get_local_id(0);
    const ulong groupRow = firstRow + (ulong)get_group_id(0) * TILE_LINES;
    const int len = (int)n;
    const int tiles = (len + TILE_SAMPLES - 1) / TILE_SAMPLES;
    if (len < 2) return; // uniform over the group: one sample is its own coefficient

    // Lanes past the last row read zeros, not stale local memory.
    for (int k = 0; k < TILE_SAMPLES; ++k) tile[k][lane] = 0.0f;
    barrier(CLK_LOCAL_MEM_FENCE);

    float c = 0.0f, before = 0.0f;
    for (int t = 0; t < tiles; ++t) {
        const int x0 = t * TILE_SAMPLES, width = min(TILE_SAMPLES, len - x0);
        bspline_tile_load(tile, data, n, rows, groupRow, x0, width, lane);
        barrier(CLK_LOCAL_MEM_FENCE);
        int k = 0;
        if (t == 0) {
            float head[BSPLINE_HORIZON];
            for (int h = 0; h < min(len, BSPLINE_HORIZON); ++h) head[h] = tile[h][lane];
            c = before = bspline_causal_init(head, len);
            tile[0][lane] = c;
            k = 1;
        }
        for (; k < width; ++k) {
            before = c;
            c = bspline_causal_step(tile[k][lane], c);
            tile[k][lane] = c;
        }
        if (t == tiles - 1) { // the last tile: its anticausal sweep while it is here
            c = bspline_anticausal_init(c, before);
            tile[width - 1][lane] = c;
            for (k = width - 2; k >= 0; --k) {
                c = bspline_anticausal_step(c, tile[k][lane]);
                tile[k][lane] = c;
            }
        }
        barrier(CLK_LOCAL_MEM_FENCE);
        bspline_tile_store(tile, data, n, rows, groupRow, x0, width, lane);
        barrier(CLK_LOCAL_MEM_FENCE);
    }
    for (int t = tiles - 2; t >= 0; --t) {
        const int x0 = t * TILE_SAMPLES; // a whole tile: only the last may be partial
        bspline_tile_load(tile, data, n, rows, groupRow, x0, TILE_SAMPLES, lane);
        barrier(CLK_LOCAL_MEM_FENCE);
        for (int k = TILE_SAMPLES - 1; k >= 0; --k) {
            c = bspline_anticausal_step(c, tile[k][lane]);
            tile[k][lane] = c;
        }
        barrier(CLK_LOCAL_MEM_FENCE);
        bspline_tile_store(tile, data, n, rows, groupRow, x0, TILE_SAMPLES, lane);
        barrier(CLK_LOCAL_MEM_FENCE);
    }
}

// Work-item g of a copy kernel below moves elements g * run .. g * run + run - 1 of a row, for
// every z slice of its slab. run = 1 on a GPU: neighbouring work-items on neighbouring floats.
// run = the row on a CPU: each work-item walks contiguous memory (a work-item per element
// made PoCL dispatch hundreds of thousands of groups; one per column walked a page per slice).

// Narrow samples (sample - offset in 1 or 2 bytes, narrow_samples.hpp) widened to float:
// float(u) + offset, exact (both integers within 2^24), the host's SampleGrid::operator[].
// The slice is the row here; the range is rounded up to the work-group.
// One body for both widths (OpenCL C has no templates).
#define BSPLINE_WIDEN_KERNEL(name, narrow_type)                                                              \
    __kernel void name(__global const narrow_type *narrow, __global float *out, const ulong slice,          \
                       const float offset, const uint firstK, const uint countK, const uint run) {          \
        const ulong i0 = (ulong)get_global_id(0) * run;                                                      \
        if (i0 >= slice) return;                                                                             \
        const ulong i1 = min(slice, i0 + run);                                                               \
        for (ulong k = firstK; k < (ulong)firstK + countK; ++k)                                              \
            for (ulong i = k * slice + i0; i < k * slice + i1; ++i) out[i] = (float)narrow[i] + offset;      \
    }
BSPLINE_WIDEN_KERNEL(bspline_widen_uchar, uchar)
BSPLINE_WIDEN_KERNEL(bspline_widen_ushort, ushort)

// The coefficients padded by one before and two after on each axis with the mirror boundary
// (p = n + 3 per axis), so the ray caster's 4x4x4 footprint around any clamped position stays
// inside: out(i, j, k) = c(mirror(i - 1), mirror(j - 1), mirror(k - 1)). A copy, so the same
// bits as the host's padMirror. Work-item (g, j): row j of padded slices firstK .. firstK +
// countK - 1, elements g * run on. The range is rounded up to the work-group.
__kernel void bspline_pad_mirror(__global const float *c, __global float *out, const int nx, const int ny,
                                 const int nz, const int firstK, const int countK, const int run) {
    const int i0 = (int)get_global_id(0) * run, j = (int)get_global_id(1);
    const int px = nx + 3, py = ny + 3;
    if (i0 >= px || j >= py) return;
    const int i1 = min(px, i0 + run);
    const ulong plane = (ulong)nx * (ulong)ny;
    for (int k = firstK; k < firstK + countK; ++k) {
        __global const float *from = c + (ulong)bspline_mirror_index(k - 1, nz) * plane +
                                     (ulong)bspline_mirror_index(j - 1, ny) * (ulong)nx;
        __global float *to = out + ((ulong)k * (ulong)py + (ulong)j) * (ulong)px;
        for (int i = i0; i < i1; ++i) {
            // Inside the volume the mirror is the identity; only the 3 pad columns fold.
            const int si = i >= 1 && i <= nx ? i - 1 : bspline_mirror_index(i - 1, nx);
            to[i] = from[si];
        }
    }
}
