/* Prometheus counters and histograms of the daemon, updated lock-free from HTTP threads.
 *
 * Requests are counted per route template (the route table's index), method and status
 * code; latencies go into one histogram per route. The standard process_* families
 * (memory, file descriptors, CPU time, start time) are read from /proc/self at scrape time,
 * as Prometheus client libraries do. */
#ifndef FG_DAEMON_METRICS_H
#define FG_DAEMON_METRICS_H

#include <stddef.h>

#include "decoder/decoder.h"

#define FG_METRICS_MAX_ROUTES 64

/* Names a route slot before the server starts; route is the path template. */
void fg_metrics_set_route(int idx, const char *method, const char *route);

/* Records one finished request. idx < 0 stands for "no route matched". */
void fg_metrics_observe_request(int idx, int status, double seconds);

void fg_metrics_add_frames_ingested(unsigned n);
void fg_metrics_count_reload(int ok);

/* Training: steps taken by every job since start, and the samples per second of the last
 * step measured. */
void fg_metrics_add_training_steps(unsigned n);
void fg_metrics_set_training_samples_per_s(double samples_per_s);

/* CLIP: embeddings computed over HTTP, by kind; frames whose features a training computed
 * with CLIP or read from its cache; loads of the [clip] files at start-up and reloads. */
typedef enum {
  FG_METRICS_CLIP_TEXT = 0,
  FG_METRICS_CLIP_IMAGE_DENSE,
  FG_METRICS_CLIP_IMAGE_POOLED,
  FG_METRICS_CLIP_KINDS
} fg_metrics_clip_kind;
void fg_metrics_add_clip_embeddings(fg_metrics_clip_kind kind, unsigned n);
void fg_metrics_add_clip_feature_frames(unsigned computed, unsigned cached);
void fg_metrics_count_clip_load(int ok);

/* Heatmaps: served by format (POST /v1/scenes/{s}/heatmap) and as renders; builds of voxel
 * feature caches and the seconds they took. */
typedef enum {
  FG_METRICS_HEATMAP_JSON = 0,
  FG_METRICS_HEATMAP_NPY,
  FG_METRICS_HEATMAP_PLY,
  FG_METRICS_HEATMAP_RENDER,
  FG_METRICS_HEATMAP_KINDS
} fg_metrics_heatmap_kind;
void fg_metrics_count_heatmap(fg_metrics_heatmap_kind kind);
void fg_metrics_add_voxel_build(double seconds);

/* Why the HTTP layer closed a connection: http_conns.h's fg_conn_reason, value for value
 * (http.c asserts it), as the labels of fieldgrip_http_connections_closed_total. */
typedef enum {
  FG_METRICS_CLOSE_SHED = 0,
  FG_METRICS_CLOSE_HEADER_TIMEOUT,
  FG_METRICS_CLOSE_IDLE_TIMEOUT,
  FG_METRICS_CLOSE_BODY_TOO_SLOW,
  FG_METRICS_CLOSE_REASONS
} fg_metrics_close_reason;

/* The HTTP layer: connections open now; connections it closed, by reason; offload threads,
 * handlers running and requests queued; requests refused 503 server_busy because the queue
 * was full. */
void fg_metrics_add_http_connections(int delta);
void fg_metrics_count_http_closed(int reason, size_t n);
void fg_metrics_set_offload(int threads, int running, int queued);
void fg_metrics_count_offload_rejected(void);

/* Job states, in the order of the gauge's labels (jobs.h uses the same order). */
#define FG_METRICS_JOB_STATES 5

/* Gauges the renderer asks for at scrape time. */
typedef struct fg_metrics_gauges {
  size_t scenes;
  size_t frames;
  size_t trained_scenes;                /* scenes holding a trained field */
  size_t fields_loaded;                 /* trained fields in memory ([state] max_loaded_fields) */
  size_t max_loaded_fields;             /* 0: no limit */
  unsigned long long field_loads;       /* fields loaded again on demand since start */
  unsigned long long field_evictions;   /* fields evicted to stay within the limit */
  int clip_loaded;                      /* a CLIP model is being served */
  size_t voxel_cache_bytes;             /* heap bytes of every voxel feature cache */
  size_t jobs[FG_METRICS_JOB_STATES];   /* jobs known, by state (queued, running, done,
                                           failed, cancelled) */
  fg_decoder_stats decoder;             /* the image decoder pool */
} fg_metrics_gauges;

/* Renders the text exposition format into a malloc'd NUL-terminated buffer the caller owns;
 * NULL on allocation failure. */
char *fg_metrics_render(const fg_metrics_gauges *g, size_t *len);

#endif
