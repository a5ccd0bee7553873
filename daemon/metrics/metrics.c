#include "metrics.h"

#include "config.h"
#include "core/strbuf.h"

#include <dirent.h>
#include <stdatomic.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/resource.h>
#include <unistd.h>

/* Status codes the daemon answers with get their own counter; anything else lands in
 * the last slot and is reported as "other". */
static const int statuses[] = {200, 201, 202, 204, 400, 401, 403, 404, 405,
                               409, 413, 415, 422, 500, 501, 502, 503, 504, 507};
#define N_STATUS (sizeof statuses / sizeof statuses[0] + 1)

static const double buckets[] = {0.0005, 0.001, 0.0025, 0.005, 0.01, 0.025,
                                 0.05,   0.1,   0.25,   0.5,   1,    2.5, 5, 10};
#define N_BUCKETS (sizeof buckets / sizeof buckets[0])

/* Slot FG_METRICS_MAX_ROUTES holds requests that matched no route. */
#define N_SLOTS (FG_METRICS_MAX_ROUTES + 1)

static struct {
  const char *method, *route;
  atomic_ullong by_status[N_STATUS];
  atomic_ullong bucket[N_BUCKETS];
  atomic_ullong count;
  atomic_ullong sum_us;
} slots[N_SLOTS];

static atomic_ullong frames_ingested;
static atomic_ullong reloads_ok, reloads_failed;
static atomic_ullong training_steps;
static _Atomic double training_samples_per_s;
static atomic_ullong clip_embeddings[FG_METRICS_CLIP_KINDS];
static atomic_ullong clip_frames_computed, clip_frames_cached;
static atomic_ullong clip_loads_ok, clip_loads_failed;
static atomic_ullong heatmaps[FG_METRICS_HEATMAP_KINDS];
static atomic_ullong voxel_builds, voxel_build_us;
static atomic_llong http_connections;
static atomic_ullong http_closed[FG_METRICS_CLOSE_REASONS];
static atomic_int offload_threads, offload_running, offload_queued;
static atomic_ullong offload_rejected;

void fg_metrics_add_http_connections(int delta) {
  atomic_fetch_add_explicit(&http_connections, delta, memory_order_relaxed);
}

void fg_metrics_count_http_closed(int reason, size_t n) {
  if (reason < 0 || reason >= FG_METRICS_CLOSE_REASONS) return;
  atomic_fetch_add_explicit(&http_closed[reason], n, memory_order_relaxed);
}

void fg_metrics_set_offload(int threads, int running, int queued) {
  atomic_store_explicit(&offload_threads, threads, memory_order_relaxed);
  atomic_store_explicit(&offload_running, running, memory_order_relaxed);
  atomic_store_explicit(&offload_queued, queued, memory_order_relaxed);
}

void fg_metrics_count_offload_rejected(void) {
  atomic_fetch_add_explicit(&offload_rejected, 1, memory_order_relaxed);
}

void fg_metrics_set_route(int idx, const char *method, const char *route) {
  if (idx < 0 || idx >= FG_METRICS_MAX_ROUTES) return;
  slots[idx].method = method;
  slots[idx].route = route;
}

void fg_metrics_observe_request(int idx, int status, double seconds) {
  int s = (idx < 0 || idx >= FG_METRICS_MAX_ROUTES) ? FG_METRICS_MAX_ROUTES : idx;
  size_t k = N_STATUS - 1;
  for (size_t i = 0; i < N_STATUS - 1; i++)
    if (statuses[i] == status) k = i;
  atomic_fetch_add_explicit(&slots[s].by_status[k], 1, memory_order_relaxed);
  for (size_t b = 0; b < N_BUCKETS; b++)
    if (seconds <= buckets[b]) {
      atomic_fetch_add_explicit(&slots[s].bucket[b], 1, memory_order_relaxed);
      break;
    }
  atomic_fetch_add_explicit(&slots[s].count, 1, memory_order_relaxed);
  atomic_fetch_add_explicit(&slots[s].sum_us, (unsigned long long)(seconds * 1e6),
                            memory_order_relaxed);
}

void fg_metrics_add_frames_ingested(unsigned n) { atomic_fetch_add(&frames_ingested, n); }

void fg_metrics_count_reload(int ok) { atomic_fetch_add(ok ? &reloads_ok : &reloads_failed, 1); }

void fg_metrics_add_training_steps(unsigned n) { atomic_fetch_add(&training_steps, n); }

void fg_metrics_set_training_samples_per_s(double v) { atomic_store(&training_samples_per_s, v); }

void fg_metrics_add_clip_embeddings(fg_metrics_clip_kind kind, unsigned n) {
  if (kind >= 0 && kind < FG_METRICS_CLIP_KINDS) atomic_fetch_add(&clip_embeddings[kind], n);
}

void fg_metrics_add_clip_feature_frames(unsigned computed, unsigned cached) {
  atomic_fetch_add(&clip_frames_computed, computed);
  atomic_fetch_add(&clip_frames_cached, cached);
}

void fg_metrics_count_clip_load(int ok) {
  atomic_fetch_add(ok ? &clip_loads_ok : &clip_loads_failed, 1);
}

void fg_metrics_count_heatmap(fg_metrics_heatmap_kind kind) {
  if (kind >= 0 && kind < FG_METRICS_HEATMAP_KINDS) atomic_fetch_add(&heatmaps[kind], 1);
}

void fg_metrics_add_voxel_build(double seconds) {
  atomic_fetch_add(&voxel_builds, 1);
  atomic_fetch_add(&voxel_build_us, (unsigned long long)(seconds > 0 ? seconds * 1e6 : 0));
}

/* ---------------------------------------------------------------- process metrics */

/* What /proc/self says about this process; a field that could not be read is negative and
 * its family is left out rather than reported as 0. */
typedef struct proc_sample {
  double cpu_s, start_time_s;
  double resident_bytes, virtual_bytes;
  double open_fds, max_fds;
} proc_sample;

/* Reads the whole of a small /proc file into buf (NUL-terminated). 0 or -1. */
static int read_small(const char *path, char *buf, size_t size) {
  FILE *f = fopen(path, "re");
  if (!f) return -1;
  size_t n = fread(buf, 1, size - 1, f);
  fclose(f);
  buf[n] = '\0';
  return n > 0 ? 0 : -1;
}

/* The boot time (btime of /proc/stat) in seconds since the epoch, or -1. */
static double boot_time_s(void) {
  FILE *f = fopen("/proc/stat", "re");
  if (!f) return -1;
  char line[256];
  double bt = -1;
  while (fgets(line, sizeof line, f))
    if (strncmp(line, "btime ", 6) == 0) {
      bt = strtod(line + 6, NULL);
      break;
    }
  fclose(f);
  return bt;
}

static void proc_read(proc_sample *s) {
  s->cpu_s = s->start_time_s = s->resident_bytes = s->virtual_bytes = -1;
  s->open_fds = s->max_fds = -1;
  const double tick_hz = (double)sysconf(_SC_CLK_TCK);
  const double page_bytes = (double)sysconf(_SC_PAGESIZE);
  char buf[1024];
  /* stat: "pid (comm) state ..."; comm may hold spaces and parentheses, so the fields are
   * counted from the last ')'. utime and stime are fields 14 and 15, starttime 22. */
  if (read_small("/proc/self/stat", buf, sizeof buf) == 0 && tick_hz > 0) {
    const char *p = strrchr(buf, ')');
    unsigned long long utime = 0, stime = 0, start = 0;
    if (p && sscanf(p + 2, "%*c %*d %*d %*d %*d %*d %*u %*u %*u %*u %*u %llu %llu %*d %*d "
                           "%*d %*d %*d %*d %llu", &utime, &stime, &start) == 3) {
      s->cpu_s = (double)(utime + stime) / tick_hz;
      const double bt = boot_time_s();
      if (bt > 0) s->start_time_s = bt + (double)start / tick_hz;
    }
  }
  /* statm: size and resident, in pages */
  unsigned long long size_pages, resident_pages;
  if (read_small("/proc/self/statm", buf, sizeof buf) == 0 && page_bytes > 0 &&
      sscanf(buf, "%llu %llu", &size_pages, &resident_pages) == 2) {
    s->virtual_bytes = (double)size_pages * page_bytes;
    s->resident_bytes = (double)resident_pages * page_bytes;
  }
  DIR *d = opendir("/proc/self/fd");
  if (d) {
    double n = 0;
    for (struct dirent *e; (e = readdir(d)) != NULL;)
      if (e->d_name[0] != '.') n++;
    s->open_fds = n - 1; /* not the one that lists them */
    closedir(d);
  }
  struct rlimit rl;
  if (getrlimit(RLIMIT_NOFILE, &rl) == 0)
    s->max_fds = rl.rlim_cur == RLIM_INFINITY ? -1 : (double)rl.rlim_cur;
}

/* One process_* family of one sample, unless it could not be read. */
static void proc_family(fg_strbuf *sb, const char *name, const char *type, const char *help,
                        double v) {
  if (v < 0) return;
  fg_strbuf_printf(sb, "# HELP %s %s\n# TYPE %s %s\n%s %.17g\n", name, help, name, type, name, v);
}

static void render_process(fg_strbuf *sb) {
  proc_sample s;
  proc_read(&s);
  proc_family(sb, "process_cpu_seconds_total", "counter",
              "Total user and system CPU time spent in seconds.", s.cpu_s);
  proc_family(sb, "process_open_fds", "gauge", "Number of open file descriptors.",
              s.open_fds);
  proc_family(sb, "process_max_fds", "gauge", "Maximum number of open file descriptors.",
              s.max_fds);
  proc_family(sb, "process_virtual_memory_bytes", "gauge", "Virtual memory size in bytes.",
              s.virtual_bytes);
  proc_family(sb, "process_resident_memory_bytes", "gauge", "Resident memory size in bytes.",
              s.resident_bytes);
  proc_family(sb, "process_start_time_seconds", "gauge",
              "Start time of the process since unix epoch in seconds.", s.start_time_s);
}

/* The image decoder pool (decoder.h). */
static void render_decoder(fg_strbuf *sb, const fg_decoder_stats *d) {
  static const char *const results[FG_DECODER_RESULTS] = {"ok", "refused", "crashed",
                                                          "timeout", "error"};
  fg_strbuf_printf(sb, "# HELP fieldgrip_decoder_processes Image decoder child processes alive, by "
                "state.\n# TYPE fieldgrip_decoder_processes gauge\n"
                "fieldgrip_decoder_processes{state=\"idle\"} %d\n"
                "fieldgrip_decoder_processes{state=\"busy\"} %d\n", d->idle, d->busy);
  fg_strbuf_printf(sb, "# HELP fieldgrip_decoder_starts_total Image decoder child processes started "
                "(on demand, and in place of one that died).\n"
                "# TYPE fieldgrip_decoder_starts_total counter\n"
                "fieldgrip_decoder_starts_total %llu\n", (unsigned long long)d->started);
  fg_strbuf_printf(sb, "# HELP fieldgrip_decoder_requests_total Images decoded or encoded in the "
                "decoder children, by result: ok; refused (not a valid image, or too large "
                "for a child's memory); crashed (the child died on it); timeout (ended for "
                "taking too long, in wall or CPU time); error (no child could run it).\n"
                "# TYPE fieldgrip_decoder_requests_total counter\n");
  for (int i = 0; i < FG_DECODER_RESULTS; i++)
    fg_strbuf_printf(sb, "fieldgrip_decoder_requests_total{result=\"%s\"} %llu\n", results[i],
              (unsigned long long)d->requests[i]);
  fg_strbuf_printf(sb, "# HELP fieldgrip_decoder_idle_deaths_total Image decoder children found dead "
                "while idle (killed from outside, out of memory); each is replaced.\n"
                "# TYPE fieldgrip_decoder_idle_deaths_total counter\n"
                "fieldgrip_decoder_idle_deaths_total %llu\n", (unsigned long long)d->died_idle);
}

char *fg_metrics_render(const fg_metrics_gauges *g, size_t *len) {
  fg_strbuf sb = {0};
  fg_strbuf_reserve(&sb, 8192);
  fg_strbuf_printf(&sb, "# HELP fieldgrip_build_info Version of the running daemon.\n"
                 "# TYPE fieldgrip_build_info gauge\n"
                 "fieldgrip_build_info{version=\"%s\"} 1\n", FG_VERSION);
  fg_strbuf_printf(&sb, "# HELP fieldgrip_http_requests_total HTTP requests answered, by route template, "
                 "method and status code.\n# TYPE fieldgrip_http_requests_total counter\n");
  for (int s = 0; s < N_SLOTS; s++) {
    const char *route = s == FG_METRICS_MAX_ROUTES ? "unmatched" : slots[s].route;
    const char *method = s == FG_METRICS_MAX_ROUTES ? "any" : slots[s].method;
    if (!route) continue;
    for (size_t k = 0; k < N_STATUS; k++) {
      unsigned long long v = atomic_load(&slots[s].by_status[k]);
      if (v == 0) continue;
      char code[16];
      if (k == N_STATUS - 1) snprintf(code, sizeof code, "other");
      else snprintf(code, sizeof code, "%d", statuses[k]);
      fg_strbuf_printf(&sb, "fieldgrip_http_requests_total{route=\"%s\",method=\"%s\",code=\"%s\"} %llu\n",
                route, method, code, v);
    }
  }
  fg_strbuf_printf(&sb, "# HELP fieldgrip_http_request_duration_seconds Time from the request's "
                 "headers to the end of its response, by route template.\n"
                 "# TYPE fieldgrip_http_request_duration_seconds histogram\n");
  for (int s = 0; s < N_SLOTS; s++) {
    const char *route = s == FG_METRICS_MAX_ROUTES ? "unmatched" : slots[s].route;
    const char *method = s == FG_METRICS_MAX_ROUTES ? "any" : slots[s].method;
    unsigned long long count = atomic_load(&slots[s].count);
    if (!route || count == 0) continue;
    unsigned long long cum = 0;
    for (size_t b = 0; b < N_BUCKETS; b++) {
      cum += atomic_load(&slots[s].bucket[b]);
      fg_strbuf_printf(&sb,
                "fieldgrip_http_request_duration_seconds_bucket{route=\"%s\",method=\"%s\","
                "le=\"%g\"} %llu\n", route, method, buckets[b], cum);
    }
    fg_strbuf_printf(&sb,
              "fieldgrip_http_request_duration_seconds_bucket{route=\"%s\",method=\"%s\","
              "le=\"+Inf\"} %llu\n"
              "fieldgrip_http_request_duration_seconds_sum{route=\"%s\",method=\"%s\"} %.6f\n"
              "fieldgrip_http_request_duration_seconds_count{route=\"%s\",method=\"%s\"} %llu\n",
              route, method, count, route, method, (double)atomic_load(&slots[s].sum_us) / 1e6,
              route, method, count);
  }
  static const char *const close_reasons[FG_METRICS_CLOSE_REASONS] = {
    [FG_METRICS_CLOSE_SHED] = "shed", [FG_METRICS_CLOSE_HEADER_TIMEOUT] = "header_timeout",
    [FG_METRICS_CLOSE_IDLE_TIMEOUT] = "idle_timeout",
    [FG_METRICS_CLOSE_BODY_TOO_SLOW] = "body_too_slow"};
  fg_strbuf_printf(&sb, "# HELP fieldgrip_http_connections Client connections open, this one "
                 "included.\n# TYPE fieldgrip_http_connections gauge\n"
                 "fieldgrip_http_connections %lld\n"
                 "# HELP fieldgrip_http_connections_closed_total Client connections the daemon "
                 "closed: shed at [http] max_connections, or too slow, by reason.\n"
                 "# TYPE fieldgrip_http_connections_closed_total counter\n",
            atomic_load(&http_connections));
  for (int r = 0; r < FG_METRICS_CLOSE_REASONS; r++)
    fg_strbuf_printf(&sb, "fieldgrip_http_connections_closed_total{reason=\"%s\"} %llu\n",
              close_reasons[r], atomic_load(&http_closed[r]));
  fg_strbuf_printf(&sb, "# HELP fieldgrip_http_offload_threads Threads that run long requests.\n"
                 "# TYPE fieldgrip_http_offload_threads gauge\nfieldgrip_http_offload_threads %d\n"
                 "# HELP fieldgrip_http_offload_running Long requests running on them now.\n"
                 "# TYPE fieldgrip_http_offload_running gauge\nfieldgrip_http_offload_running %d\n"
                 "# HELP fieldgrip_http_offload_queued Long requests waiting for a thread.\n"
                 "# TYPE fieldgrip_http_offload_queued gauge\nfieldgrip_http_offload_queued %d\n"
                 "# HELP fieldgrip_http_offload_rejected_total Long requests answered 503 "
                 "server_busy because [http] max_queued_requests were waiting.\n"
                 "# TYPE fieldgrip_http_offload_rejected_total counter\n"
                 "fieldgrip_http_offload_rejected_total %llu\n",
            atomic_load(&offload_threads), atomic_load(&offload_running),
            atomic_load(&offload_queued), atomic_load(&offload_rejected));
  fg_strbuf_printf(&sb, "# HELP fieldgrip_scenes Scenes in the state dir.\n# TYPE fieldgrip_scenes gauge\n"
                 "fieldgrip_scenes %zu\n", g->scenes);
  fg_strbuf_printf(&sb, "# HELP fieldgrip_frames Frames stored, over all scenes.\n"
                 "# TYPE fieldgrip_frames gauge\nfieldgrip_frames %zu\n", g->frames);
  fg_strbuf_printf(&sb, "# HELP fieldgrip_frames_ingested_total Frames accepted by upload or import "
                 "since start.\n# TYPE fieldgrip_frames_ingested_total counter\n"
                 "fieldgrip_frames_ingested_total %llu\n", atomic_load(&frames_ingested));
  fg_strbuf_printf(&sb, "# HELP fieldgrip_config_reloads_total Configuration reloads on SIGHUP, by "
                 "result.\n# TYPE fieldgrip_config_reloads_total counter\n"
                 "fieldgrip_config_reloads_total{result=\"ok\"} %llu\n"
                 "fieldgrip_config_reloads_total{result=\"failed\"} %llu\n",
            atomic_load(&reloads_ok), atomic_load(&reloads_failed));
  static const char *const job_states[FG_METRICS_JOB_STATES] = {"queued", "running", "done",
                                                                "failed", "cancelled"};
  fg_strbuf_printf(&sb, "# HELP fieldgrip_jobs Jobs the daemon knows (this run's, and each scene's "
                 "last one from before), by state.\n# TYPE fieldgrip_jobs gauge\n");
  for (int i = 0; i < FG_METRICS_JOB_STATES; i++)
    fg_strbuf_printf(&sb, "fieldgrip_jobs{state=\"%s\"} %zu\n", job_states[i], g->jobs[i]);
  fg_strbuf_printf(&sb, "# HELP fieldgrip_trained_scenes Scenes holding a trained field.\n"
                 "# TYPE fieldgrip_trained_scenes gauge\nfieldgrip_trained_scenes %zu\n",
            g->trained_scenes);
  fg_strbuf_printf(&sb, "# HELP fieldgrip_fields_loaded Trained fields in memory, with their voxel "
                 "caches; at most fieldgrip_fields_loaded_max unless that is 0 (no limit).\n"
                 "# TYPE fieldgrip_fields_loaded gauge\nfieldgrip_fields_loaded %zu\n"
                 "# HELP fieldgrip_fields_loaded_max [state] max_loaded_fields.\n"
                 "# TYPE fieldgrip_fields_loaded_max gauge\nfieldgrip_fields_loaded_max %zu\n"
                 "# HELP fieldgrip_field_loads_total Trained fields loaded again from their "
                 "checkpoint on demand since start.\n"
                 "# TYPE fieldgrip_field_loads_total counter\nfieldgrip_field_loads_total %llu\n"
                 "# HELP fieldgrip_field_evictions_total Trained fields evicted from memory to "
                 "stay within [state] max_loaded_fields since start.\n"
                 "# TYPE fieldgrip_field_evictions_total counter\n"
                 "fieldgrip_field_evictions_total %llu\n",
            g->fields_loaded, g->max_loaded_fields, g->field_loads, g->field_evictions);
  fg_strbuf_printf(&sb, "# HELP fieldgrip_training_steps_total Training steps taken since start, over "
                 "all jobs.\n# TYPE fieldgrip_training_steps_total counter\n"
                 "fieldgrip_training_steps_total %llu\n", atomic_load(&training_steps));
  fg_strbuf_printf(&sb, "# HELP fieldgrip_training_samples_per_second Samples per second of the last "
                 "training step measured (0 before any).\n"
                 "# TYPE fieldgrip_training_samples_per_second gauge\n"
                 "fieldgrip_training_samples_per_second %.6g\n",
            atomic_load(&training_samples_per_s));
  fg_strbuf_printf(&sb, "# HELP fieldgrip_clip_model_loaded Whether a CLIP model ([clip]) is being "
                 "served.\n# TYPE fieldgrip_clip_model_loaded gauge\n"
                 "fieldgrip_clip_model_loaded %d\n", g->clip_loaded ? 1 : 0);
  fg_strbuf_printf(&sb, "# HELP fieldgrip_clip_loads_total Loads of the [clip] weights and vocabulary "
                 "at start-up and reloads, by result.\n# TYPE fieldgrip_clip_loads_total counter\n"
                 "fieldgrip_clip_loads_total{result=\"ok\"} %llu\n"
                 "fieldgrip_clip_loads_total{result=\"failed\"} %llu\n",
            atomic_load(&clip_loads_ok), atomic_load(&clip_loads_failed));
  fg_strbuf_printf(&sb, "# HELP fieldgrip_clip_embeddings_total CLIP embeddings computed for POST "
                 "/v1/embed/text (one per text) and /v1/embed/image, by kind.\n"
                 "# TYPE fieldgrip_clip_embeddings_total counter\n"
                 "fieldgrip_clip_embeddings_total{kind=\"text\"} %llu\n"
                 "fieldgrip_clip_embeddings_total{kind=\"image_dense\"} %llu\n"
                 "fieldgrip_clip_embeddings_total{kind=\"image_pooled\"} %llu\n",
            atomic_load(&clip_embeddings[FG_METRICS_CLIP_TEXT]),
            atomic_load(&clip_embeddings[FG_METRICS_CLIP_IMAGE_DENSE]),
            atomic_load(&clip_embeddings[FG_METRICS_CLIP_IMAGE_POOLED]));
  fg_strbuf_printf(&sb, "# HELP fieldgrip_clip_feature_frames_total Frames whose CLIP features a "
                 "training computed, or read from the scene's cache.\n"
                 "# TYPE fieldgrip_clip_feature_frames_total counter\n"
                 "fieldgrip_clip_feature_frames_total{source=\"computed\"} %llu\n"
                 "fieldgrip_clip_feature_frames_total{source=\"cached\"} %llu\n",
            atomic_load(&clip_frames_computed), atomic_load(&clip_frames_cached));
  fg_strbuf_printf(&sb, "# HELP fieldgrip_heatmaps_total Heatmaps served: POST "
                 "/v1/scenes/{s}/heatmap by format, and renders with output heatmap.\n"
                 "# TYPE fieldgrip_heatmaps_total counter\n"
                 "fieldgrip_heatmaps_total{format=\"json\"} %llu\n"
                 "fieldgrip_heatmaps_total{format=\"npy\"} %llu\n"
                 "fieldgrip_heatmaps_total{format=\"ply\"} %llu\n"
                 "fieldgrip_heatmaps_total{format=\"render\"} %llu\n",
            atomic_load(&heatmaps[FG_METRICS_HEATMAP_JSON]),
            atomic_load(&heatmaps[FG_METRICS_HEATMAP_NPY]),
            atomic_load(&heatmaps[FG_METRICS_HEATMAP_PLY]),
            atomic_load(&heatmaps[FG_METRICS_HEATMAP_RENDER]));
  fg_strbuf_printf(&sb, "# HELP fieldgrip_voxel_cache_builds_total Voxel feature caches built (the "
                 "trained field sampled on the workspace grid).\n"
                 "# TYPE fieldgrip_voxel_cache_builds_total counter\n"
                 "fieldgrip_voxel_cache_builds_total %llu\n"
                 "# HELP fieldgrip_voxel_cache_build_seconds_total Wall time spent building voxel "
                 "feature caches.\n# TYPE fieldgrip_voxel_cache_build_seconds_total counter\n"
                 "fieldgrip_voxel_cache_build_seconds_total %.6f\n"
                 "# HELP fieldgrip_voxel_cache_bytes Heap bytes of the voxel feature caches "
                 "and their grasp fields held, over all scenes.\n"
                 "# TYPE fieldgrip_voxel_cache_bytes gauge\n"
                 "fieldgrip_voxel_cache_bytes %zu\n",
            atomic_load(&voxel_builds), (double)atomic_load(&voxel_build_us) / 1e6,
            g->voxel_cache_bytes);
  render_decoder(&sb, &g->decoder);
  render_process(&sb);
  return fg_strbuf_take(&sb, len);
}
