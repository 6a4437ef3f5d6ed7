// Cubic B-spline prefilter (Unser; Ruijters & Thevenaz), the OpenCL twin of
// renderer/common/bspline_prefilter.cpp: one work-item filters one line in place, one launch per
// axis. Mirror (whole-sample symmetric) boundaries; exact on any n >= 1.

// Pole of the cubic B-spline's inverse filter, sqrt(3) - 2.
#define BSPLINE_POLE (-0.26794919243112270f)

// Index of coefficient k under mirror boundaries on an axis of n samples (n >= 2 here).
int bspline_mirror_index(int k, int n) {
    const int period = 2 * n - 2;
    k %= period;
    if (k < 0) k += period;
    return k < n ? k : period - k;
}

// The line of work-item (b, a) starts at b * strideB + a * strideA; its n samples lie
// `stride` apart. A 2-D range keeps every index product in 64 bits without a division.
__kernel void bspline_prefilter_axis(__global float *data, const uint n, const ulong stride,
                                     const ulong strideB, const ulong strideA) {
    if (n < 2) return; // one sample: the coefficient is the sample
    __global float *line = data + (ulong)get_global_id(0) * strideB + (ulong)get_global_id(1) * strideA;
    const float z = BSPLINE_POLE;
    const float gain = (1.0f - z) * (1.0f - 1.0f / z); // = 6: the filter's DC gain
    const int len = (int)n;

    for (int k = 0; k < len; ++k) line[k * stride] *= gain;

    // Causal initialisation: sum over the mirrored signal (period 2n - 2), truncated where
    // z^k falls below float's epsilon (13 terms), exact otherwise: the C++ horizon.
    const int horizon = (int)ceil(log(FLT_EPSILON) / log(fabs(z)));
    float sum = line[0];
    if (horizon < len) {
        float zk = z;
        for (int k = 1; k < horizon; ++k, zk *= z) sum += zk * line[k * stride];
    } else {
        const int period = 2 * len - 2;
        float zk = z;
        for (int k = 1; k < period; ++k, zk *= z) sum += zk * line[bspline_mirror_index(k, len) * stride];
        sum /= 1.0f - pown(z, period);
    }
    line[0] = sum;

    // Causal recursion c+[k] = s[k] + z * c+[k-1].
    for (int k = 1; k < len; ++k) line[k * stride] += z * line[(k - 1) * stride];

    // Anticausal initialisation for mirror boundaries, then c[k] = z * (c[k+1] - c+[k]).
    line[(len - 1) * stride] = z / (z * z - 1.0f) * (line[(len - 1) * stride] + z * line[(len - 2) * stride]);
    for (int k = len - 2; k >= 0; --k) line[k * stride] = z * (line[(k + 1) * stride] - line[k * stride]);
}
