/* Frame upload soak: bench_soak FIELDGRIPD [--frames N] [--frames-per-scene N]
 * [--sample-every N].
 *
 * Starts fieldgripd (through the integration harness: free loopback port, temporary state
 * dir, log level info) and uploads --frames frames (default 10,000), each a 64x48 RGB PNG
 * with a PINHOLE camera and a 6x8x16 float32 features .npy (small, so the loop measures the
 * daemon's per-request bookkeeping rather than image work), over one kept-alive connection.
 * The API has no endpoint that deletes one frame, so frames are deleted with their scene:
 * every --frames-per-scene uploads (default 100) the scene is deleted and created again.
 * Every --sample-every uploads (default 500) it reads the daemon's resident memory (VmRSS of
 * /proc/PID/status) and that of its image decoder children (fieldgrip-decode, started and
 * ended on demand: reported apart, not part of the daemon's figure).
 *
 * Resident memory should be flat: once the allocator's arenas and the decoder pool have
 * warmed up (the first 1000 uploads), what a frame and a scene allocate must be given back
 * when they are deleted. The target is growth_kb (VmRSS at the end minus VmRSS after 1000
 * uploads) <= 4096 kB.
 *
 * Output: a line per sample, then a summary, space-separated key=value pairs:
 *   bench=soak_sample uploads=500 scenes_deleted=5 rss_kb=... decoders_rss_kb=... seconds=...
 *   bench=soak uploads=10000 scenes_deleted=100 errors=0 uploads_per_s=... rss_kb_start=...
 *     rss_kb_at_1000=... rss_kb_end=... rss_kb_max=... growth_kb=... target_max_growth_kb=4096
 *     pass=yes|no
 * The exit status is 0 when there was no error and the growth is within the target. */
#include "training.h"

#include <curl/curl.h>
#include <dirent.h>

/* VmRSS of process pid in kB; -1 when it cannot be read (the process is gone). */
static long rss_kb(pid_t pid) {
  char path[64], line[256];
  snprintf(path, sizeof path, "/proc/%d/status", (int)pid);
  FILE *f = fopen(path, "r");
  if (!f) return -1;
  long kb = -1;
  while (fgets(line, sizeof line, f))
    if (sscanf(line, "VmRSS: %ld kB", &kb) == 1) break;
  fclose(f);
  return kb;
}

/* The summed VmRSS of pid's children, in kB. A child is listed in the "children" file of
 * the thread that forked it, so every thread's is read. */
static long children_rss_kb(pid_t pid) {
  char path[64];
  snprintf(path, sizeof path, "/proc/%d/task", (int)pid);
  DIR *d = opendir(path);
  if (!d) return 0;
  long sum = 0;
  struct dirent *e;
  while ((e = readdir(d)) != NULL) {
    if (e->d_name[0] == '.') continue;
    char *cpath = h_fmt("/proc/%d/task/%s/children", (int)pid, e->d_name);
    FILE *f = fopen(cpath, "r");
    free(cpath);
    if (!f) continue;
    int child;
    while (fscanf(f, "%d", &child) == 1) {
      long kb = rss_kb((pid_t)child);
      if (kb > 0) sum += kb;
    }
    fclose(f);
  }
  closedir(d);
  return sum;
}

static int arg_int(int argc, char **argv, const char *name, int dflt) {
  for (int i = 2; i + 1 < argc; i++)
    if (strcmp(argv[i], name) == 0) return atoi(argv[i + 1]);
  return dflt;
}

static size_t discard(char *p, size_t size, size_t n, void *ud) {
  (void)p;
  (void)ud;
  return size * n;
}

/* One frame upload on the kept-alive handle h; returns the HTTP status (0 on a transport
 * error, whose message goes to stderr). */
static long upload(CURL *h, const char *url, const uint8_t *png, size_t png_len,
                   const char *meta, const uint8_t *npy, size_t npy_len) {
  curl_mime *m = curl_mime_init(h);
  curl_mimepart *p = curl_mime_addpart(m);
  curl_mime_name(p, "image");
  curl_mime_filename(p, "image.png");
  curl_mime_type(p, "image/png");
  curl_mime_data(p, (const char *)png, png_len);
  p = curl_mime_addpart(m);
  curl_mime_name(p, "meta");
  curl_mime_type(p, "application/json");
  curl_mime_data(p, meta, CURL_ZERO_TERMINATED);
  p = curl_mime_addpart(m);
  curl_mime_name(p, "features");
  curl_mime_filename(p, "features.npy");
  curl_mime_type(p, "application/octet-stream");
  curl_mime_data(p, (const char *)npy, npy_len);
  curl_easy_setopt(h, CURLOPT_URL, url);
  curl_easy_setopt(h, CURLOPT_MIMEPOST, m);
  CURLcode rc = curl_easy_perform(h);
  long status = 0;
  if (rc == CURLE_OK) curl_easy_getinfo(h, CURLINFO_RESPONSE_CODE, &status);
  else fprintf(stderr, "bench_soak: upload: %s\n", curl_easy_strerror(rc));
  curl_easy_setopt(h, CURLOPT_MIMEPOST, NULL);
  curl_mime_free(m);
  return status;
}

/* Creates (create = 1) or deletes scene "soak"; returns 1 when the daemon answered as
 * expected. */
static int scene_op(int create) {
  h_resp *r = create ? h_post_json("/v1/scenes", "{\"name\": \"soak\"}")
                     : h_delete("/v1/scenes/soak");
  const long want = create ? 201 : 200;
  const int ok = r->status == want;
  if (!ok) fprintf(stderr, "bench_soak: scene %s -> %ld %s\n", create ? "create" : "delete",
                   r->status, r->body);
  h_resp_free(r);
  return ok;
}

int main(int argc, char **argv) {
  h_init(argc, argv);
  const int n_frames = arg_int(argc, argv, "--frames", 10000);
  const int per_scene = arg_int(argc, argv, "--frames-per-scene", 100);
  const int every = arg_int(argc, argv, "--sample-every", 500);
  if (n_frames < 1 || per_scene < 1 || every < 1) FG_TEST_FAIL("bad option value");
  h_set_log_level("info");
  h_start();
  const pid_t pid = h_pid();

  /* A few distinct frames, so that no layer could answer from a cache of the last one. */
  enum { N_VARIANTS = 8 };
  uint8_t *png[N_VARIANTS], *npy[N_VARIANTS];
  size_t png_len[N_VARIANTS], npy_len[N_VARIANTS];
  char *meta[N_VARIANTS];
  static const int shape[3] = {6, 8, 16};
  for (int v = 0; v < N_VARIANTS; v++) {
    h_png(64, 48, 3, 8, (unsigned)v + 1, 0, &png[v], &png_len[v]);
    h_npy("<f4", shape, 3, (unsigned)v, &npy[v], &npy_len[v]);
    double T[16];
    h_pose(T, 0.1 * v, 0.2, 0.3, 0.5, -0.2 + 0.05 * v, 0.4);
    meta[v] = h_meta(T, "opengl", 50, 32, 24, 64, 48);
  }

  char *url = h_fmt("http://127.0.0.1:%d/v1/scenes/soak/frames", h_port());
  CURL *h = curl_easy_init();
  if (!h) FG_TEST_FAIL("curl_easy_init failed");
  curl_easy_setopt(h, CURLOPT_WRITEFUNCTION, discard);
  curl_easy_setopt(h, CURLOPT_NOSIGNAL, 1L);
  curl_easy_setopt(h, CURLOPT_TIMEOUT, 60L);

  long errors = 0, deleted = 0;
  if (!scene_op(1)) errors++;
  const long rss_start = rss_kb(pid);
  long rss_1000 = -1, rss_max = rss_start, rss_end = rss_start;
  const double t0 = t_now();
  printf("bench=soak_sample uploads=0 scenes_deleted=0 rss_kb=%ld decoders_rss_kb=%ld "
         "seconds=0.0\n", rss_start, children_rss_kb(pid));
  for (int i = 1; i <= n_frames; i++) {
    const int v = i % N_VARIANTS;
    long st = upload(h, url, png[v], png_len[v], meta[v], npy[v], npy_len[v]);
    if (st != 201) {
      if (errors++ < 5) fprintf(stderr, "bench_soak: upload %d -> %ld\n", i, st);
    }
    if (i % per_scene == 0) {
      if (!scene_op(0) || !scene_op(1)) errors++;
      deleted++;
    }
    if (i % every == 0 || i == n_frames) {
      const long kb = rss_kb(pid);
      if (kb < 0) FG_TEST_FAIL("the daemon (pid %d) is gone after %d uploads", (int)pid, i);
      if (i <= 1000) rss_1000 = kb;
      if (kb > rss_max) rss_max = kb;
      rss_end = kb;
      printf("bench=soak_sample uploads=%d scenes_deleted=%ld rss_kb=%ld decoders_rss_kb=%ld "
             "seconds=%.1f\n", i, deleted, kb, children_rss_kb(pid), t_now() - t0);
    }
  }
  const double elapsed = t_now() - t0;
  curl_easy_cleanup(h);
  h_stop();

  if (rss_1000 < 0) rss_1000 = rss_start;
  const long growth = rss_end - rss_1000;
  const int pass = errors == 0 && growth <= 4096;
  printf("bench=soak uploads=%d scenes_deleted=%ld errors=%ld uploads_per_s=%.1f "
         "rss_kb_start=%ld rss_kb_at_1000=%ld rss_kb_end=%ld rss_kb_max=%ld growth_kb=%ld "
         "target_max_growth_kb=4096 pass=%s\n",
         n_frames, deleted, errors, n_frames / elapsed, rss_start, rss_1000, rss_end, rss_max,
         growth, pass ? "yes" : "no");
  for (int v = 0; v < N_VARIANTS; v++) {
    free(png[v]);
    free(npy[v]);
    free(meta[v]);
  }
  free(url);
  h_done();
  return pass ? 0 : 1;
}
