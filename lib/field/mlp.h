/* Small fully connected networks, as tiny-cuda-nn's FullyFusedMLP that Instant-NGP uses: no
 * biases, ReLU after every hidden layer, a linear output (the caller applies any output
 * activation: exp for density, sigmoid for colour, none for features).
 *
 * Shape. n_hidden_layers hidden layers of width n_hidden, so n_hidden_layers + 1 weight
 * matrices:
 *   layer 0:                 n_in     -> n_hidden   (n_in -> n_out when n_hidden_layers == 0)
 *   layers 1..L-1:           n_hidden -> n_hidden
 *   layer L = n_hidden_layers: n_hidden -> n_out
 * For example Instant-NGP's density net is {32, 64, 1, 16}, its colour net {32, 64, 2, 3},
 * and F3RM's feature net {32, 64, 2, 512}.
 *
 * Parameters are one float array: the layers' matrices concatenated in layer order, each
 * W_l (fan_out_l, fan_in_l) row-major, so that a layer computes out = in @ W_l^T.
 *
 * Activations. fg_mlp_forward keeps every hidden layer's output after its ReLU in `acts`,
 * (n_hidden_layers, B, n_hidden), which fg_mlp_backward reads again (ReLU' is taken from the
 * sign of the post-activation value, as tiny-cuda-nn does).
 *
 * Threads and determinism. The batch is cut into fixed chunks of rows (the cut depends only
 * on B), each chunk runs through all layers while it is in cache, and the chunks are split
 * across OpenMP threads. Weight gradients are summed per fixed group of chunks, then the
 * groups are added in group order. Every output is therefore bit-identical for any thread
 * count and timing. The fast path computes with hand-written AVX-512 kernels when the CPU has
 * AVX-512 (1.5-2x the speed of OpenBLAS on these shapes; they take up to 64 KB of stack per
 * thread), and with single-threaded OpenBLAS SGEMM per chunk otherwise (and for a forward
 * layer with fan_in > 256); results of the two paths agree to rounding, not bit for bit.
 * n_threads <= 0 takes the OpenMP default. Nothing here allocates except the reference
 * backward.
 *
 * OpenBLAS. On the SGEMM path, OpenBLAS's own thread count is set to 1 for the duration of
 * the call and restored afterwards (Debian's OpenBLAS is the pthread build, whose thread count
 * is process-wide): a concurrent SGEMM from another thread of the process then runs on one
 * thread. */
#ifndef FG_FIELD_MLP_H
#define FG_FIELD_MLP_H

#include <stddef.h>
#include <stdint.h>

#define FG_MLP_MAX_WIDTH 4096       /* limit on n_in, n_hidden and n_out */
#define FG_MLP_MAX_HIDDEN_LAYERS 16 /* limit on n_hidden_layers */

typedef struct fg_mlp_config {
  int n_in;            /* input width, 1..FG_MLP_MAX_WIDTH */
  int n_hidden;        /* hidden width, 1..FG_MLP_MAX_WIDTH */
  int n_hidden_layers; /* 0..FG_MLP_MAX_HIDDEN_LAYERS */
  int n_out;           /* output width, 1..FG_MLP_MAX_WIDTH */
} fg_mlp_config;

/* Checks cfg; returns 0 or FG_EINVAL with a detail naming the bad field. The functions below
 * assume a config that passed this check (they do not check it again). */
int fg_mlp_config_check(const fg_mlp_config *cfg);

/* Number of floats in the parameter array (and in its gradient and Adam moments). */
size_t fg_mlp_n_params(const fg_mlp_config *cfg);

/* Layer l (0..n_hidden_layers): its first float in the parameter array, and its widths. */
size_t fg_mlp_layer_offset(const fg_mlp_config *cfg, int l);
int fg_mlp_layer_fan_in(const fg_mlp_config *cfg, int l);
int fg_mlp_layer_fan_out(const fg_mlp_config *cfg, int l);

/* Initialises W (fg_mlp_n_params floats, caller-owned) uniformly in +-sqrt(6/(fan_in+fan_out))
 * per layer (Glorot/Xavier uniform, as tiny-cuda-nn) from a counter-based generator
 * (splitmix64 of seed and index): the same seed gives the same bytes on every machine. */
void fg_mlp_init(const fg_mlp_config *cfg, float *W, uint64_t seed);

/* Floats in the activation buffer of a batch of B rows: n_hidden_layers * B * n_hidden. */
size_t fg_mlp_acts_floats(const fg_mlp_config *cfg, int B);

/* Floats of backward scratch for a batch of B rows: per-group weight gradients and per-group
 * chunk buffers. It stops growing at B = 2^14 rows: 8.6 MB for the density net, 8.8 MB for
 * the colour net, 10.9 MB for the feature net. */
size_t fg_mlp_scratch_floats(const fg_mlp_config *cfg, int B);

/* Forward pass of B rows (B >= 0). W (n_params), in is (B, n_in), acts is
 * (n_hidden_layers, B, n_hidden) and receives the post-ReLU hidden outputs, out is (B, n_out).
 * All buffers are caller-owned; acts and out are overwritten. */
void fg_mlp_forward(const fg_mlp_config *cfg, const float *W, const float *in, int B,
                    float *acts, float *out, int n_threads);

/* Backward pass of the B rows that the last fg_mlp_forward saw, with the same W, in and acts.
 * dout is (B, n_out), the loss gradient with respect to out. dW (n_params) is ACCUMULATED
 * (+=); din is (B, n_in) and overwritten with the gradient with respect to in, or NULL when
 * not wanted. scratch has fg_mlp_scratch_floats(cfg, B) floats. All buffers caller-owned. */
void fg_mlp_backward(const fg_mlp_config *cfg, const float *W, const float *in,
                     const float *acts, const float *dout, int B, float *dW, float *din,
                     float *scratch, int n_threads);

/* Readable scalar references of the two passes (one thread, plain loops, one row at a time;
 * the weight gradient is summed in double). Same contracts, without scratch; the backward
 * allocates its double accumulator and returns 0 or FG_ENOMEM. For tests. */
void fg_mlp_forward_ref(const fg_mlp_config *cfg, const float *W, const float *in, int B,
                        float *acts, float *out);
int fg_mlp_backward_ref(const fg_mlp_config *cfg, const float *W, const float *in,
                         const float *acts, const float *dout, int B, float *dW, float *din);

/* Which fast path this machine takes: "avx512" or "openblas". */
const char *fg_mlp_kernel_name(void);

/* Forces the fast path, for tests and benchmarks: 0 automatic (default), 1 OpenBLAS,
 * 2 AVX-512 (falls back to OpenBLAS when the CPU lacks it). Process-wide; not thread-safe
 * against concurrent MLP calls. */
void fg_mlp_set_kernel(int which);

#endif
