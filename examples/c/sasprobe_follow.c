/* sasprobe_follow: follow a sasprobe daemon from C with libzmq, written from
 * protocol/README.md alone.
 *
 * It asks the daemon for its `status`, changes the contact stiffness with `set`, then
 * prints every pose it receives and every scene whose revision is new, until it has
 * seen --poses poses. One line per message, `key=value` fields, doubles printed so that
 * they read back exactly (%.17g).
 *
 *   sasprobe_follow --pub ENDPOINT --ctl ENDPOINT [--keys DIR] [--poses N]
 *                   [--stiffness N_PER_MM] [--timeout S]
 *
 * --keys DIR: CURVE keys for a daemon that binds TCP (server.key, client.key,
 * client.key_secret as `sasprobe keys DIR` writes them; a daemon on loopback uses the
 * user's local keys in $XDG_RUNTIME_DIR/sasprobe/). Without it: no CURVE (ipc://).
 *
 * Exit status: 0 when every message decoded, 1 on a protocol error or timeout, 2 on a
 * usage error. Build: see Makefile (cc ... $(pkg-config --cflags --libs libzmq)).
 */

#include <errno.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <zmq.h>

#define POSE_V1_BYTES 200 /* README: "Payload version 1 is exactly 200 bytes" */
#define MAX_MESSAGE (1 << 20)

/* ---- little-endian readers: the README says every number is little-endian ---- */
static uint64_t le_u(const unsigned char *p, int bytes) {
    uint64_t v = 0;
    for (int i = bytes - 1; i >= 0; i--) v = (v << 8) | p[i];
    return v;
}
static int64_t le_i64(const unsigned char *p) { return (int64_t)le_u(p, 8); }
static int32_t le_i32(const unsigned char *p) { return (int32_t)(uint32_t)le_u(p, 4); }
static double le_f64(const unsigned char *p) {
    uint64_t bits = le_u(p, 8);
    double d;
    memcpy(&d, &bits, sizeof d); /* IEEE-754 binary64 */
    return d;
}

typedef struct {
    unsigned version, flags;
    uint32_t buttons, reserved;
    uint64_t seq;
    int64_t device_t_ns, publish_t_ns;
    double proxy[3], goal[3], force[3], tip[3], orientation[4], cube_center[3], cube_half;
    int32_t touched_atom;
} pose_t;

static void vec(const unsigned char *p, double *out, int n) {
    for (int i = 0; i < n; i++) out[i] = le_f64(p + 8 * i);
}

/* The README's table, offset by offset. */
static int decode_pose(const unsigned char *b, size_t n, pose_t *p, char *why, size_t why_len) {
    if (n < 2) { snprintf(why, why_len, "pose of %zu bytes", n); return -1; }
    p->version = (unsigned)le_u(b + 0, 2);
    if (p->version < 1) { snprintf(why, why_len, "pose version %u older than 1", p->version); return -1; }
    if (n < POSE_V1_BYTES) { snprintf(why, why_len, "pose of %zu bytes, expected at least 200", n); return -1; }
    p->flags = (unsigned)le_u(b + 2, 2);
    p->buttons = (uint32_t)le_u(b + 4, 4);
    p->seq = le_u(b + 8, 8);
    p->device_t_ns = le_i64(b + 16);
    p->publish_t_ns = le_i64(b + 24);
    vec(b + 32, p->proxy, 3);
    vec(b + 56, p->goal, 3);
    vec(b + 80, p->force, 3);
    vec(b + 104, p->tip, 3);
    vec(b + 128, p->orientation, 4);
    p->touched_atom = le_i32(b + 160);
    p->reserved = (uint32_t)le_u(b + 164, 4);
    vec(b + 168, p->cube_center, 3);
    p->cube_half = le_f64(b + 192);
    return 0; /* bytes past 200 belong to newer versions: ignored */
}

static void print_vec(const char *name, const double *v, int n) {
    printf(" %s=", name);
    for (int i = 0; i < n; i++) printf("%s%.17g", i ? "," : "", v[i]);
}

static void print_pose(const pose_t *p) {
    printf("pose seq=%llu version=%u flags=%u buttons=%u device_t_ns=%lld publish_t_ns=%lld",
           (unsigned long long)p->seq, p->version, p->flags, p->buttons, (long long)p->device_t_ns,
           (long long)p->publish_t_ns);
    print_vec("proxy", p->proxy, 3);
    print_vec("goal", p->goal, 3);
    print_vec("force", p->force, 3);
    print_vec("tip", p->tip, 3);
    print_vec("orientation", p->orientation, 4);
    printf(" touched_atom=%d", p->touched_atom);
    print_vec("cube_center", p->cube_center, 3);
    printf(" cube_half=%.17g\n", p->cube_half);
}

/* ---- just enough JSON: the value after the first "key": in a text (no parser needed to print) ---- */
static const char *json_value(const char *text, const char *key) {
    char pattern[96];
    snprintf(pattern, sizeof pattern, "\"%s\":", key);
    const char *at = strstr(text, pattern);
    if (!at) return NULL;
    at += strlen(pattern);
    while (*at == ' ') at++;
    return at;
}

static void copy_token(const char *value, char *out, size_t out_len) {
    size_t i = 0;
    if (!value) { snprintf(out, out_len, "?"); return; }
    if (*value == '"') { /* a string: up to the closing quote (names and errors have no escapes we need) */
        value++;
        while (value[i] && value[i] != '"' && i + 1 < out_len) { out[i] = value[i]; i++; }
    } else {
        while (value[i] && value[i] != ',' && value[i] != '}' && value[i] != ']' && i + 1 < out_len) {
            out[i] = value[i];
            i++;
        }
    }
    out[i] = 0;
}

/* ---- CURVE keys from `sasprobe keys DIR` files (ZeroMQ's certificate format) ---- */
static int read_key(const char *dir, const char *file, const char *which, char key[41]) {
    char path[4096], line[512];
    snprintf(path, sizeof path, "%s/%s", dir, file);
    FILE *f = fopen(path, "r");
    if (!f) { fprintf(stderr, "sasprobe_follow: cannot read %s: %s\n", path, strerror(errno)); return -1; }
    int found = -1;
    while (found < 0 && fgets(line, sizeof line, f)) {
        char *at = strstr(line, which);
        char *q = at ? strchr(at, '"') : NULL;
        if (q && strlen(q + 1) >= 41 && q[41] == '"') {
            memcpy(key, q + 1, 40);
            key[40] = 0;
            found = 0;
        }
    }
    fclose(f);
    if (found < 0) fprintf(stderr, "sasprobe_follow: no %s in %s\n", which, path);
    return found;
}

static int use_keys(void *sock, const char *dir) {
    char server[41], public_key[41], secret[41];
    if (read_key(dir, "server.key", "public-key", server) || read_key(dir, "client.key", "public-key", public_key) ||
        read_key(dir, "client.key_secret", "secret-key", secret))
        return -1;
    zmq_setsockopt(sock, ZMQ_CURVE_SERVERKEY, server, 40);
    zmq_setsockopt(sock, ZMQ_CURVE_PUBLICKEY, public_key, 40);
    zmq_setsockopt(sock, ZMQ_CURVE_SECRETKEY, secret, 40);
    return 0;
}

/* ---- control: one REQ request, one reply frame (plus a data frame only for get_structure) ---- */
static int request(void *req, const char *json, char *reply, size_t reply_len) {
    if (zmq_send(req, json, strlen(json), 0) < 0) return -1;
    int n = zmq_recv(req, reply, reply_len - 1, 0);
    if (n < 0) return -1;
    reply[n < (int)reply_len - 1 ? n : (int)reply_len - 1] = 0;
    int more = 0;
    size_t more_len = sizeof more;
    zmq_getsockopt(req, ZMQ_RCVMORE, &more, &more_len);
    while (more) { /* a data frame: not asked for here */
        char skip[256];
        zmq_recv(req, skip, sizeof skip, 0);
        zmq_getsockopt(req, ZMQ_RCVMORE, &more, &more_len);
    }
    return 0;
}

static int expect_ok(const char *what, const char *reply, const char *id) {
    char ok[8], got_id[64], error[256];
    copy_token(json_value(reply, "ok"), ok, sizeof ok);
    copy_token(json_value(reply, "id"), got_id, sizeof got_id);
    if (strcmp(got_id, id) != 0) {
        fprintf(stderr, "sasprobe_follow: %s: reply id %s, sent %s\n", what, got_id, id);
        return -1;
    }
    if (strcmp(ok, "true") != 0) {
        copy_token(json_value(reply, "error"), error, sizeof error);
        fprintf(stderr, "sasprobe_follow: %s: %s\n", what, error);
        return -1;
    }
    return 0;
}

static void usage(void) {
    fprintf(stderr, "usage: sasprobe_follow --pub ENDPOINT --ctl ENDPOINT [--keys DIR] [--poses N] "
                    "[--stiffness N_PER_MM] [--timeout S]\n");
    exit(2);
}

int main(int argc, char **argv) {
    const char *pub = NULL, *ctl = NULL, *keys = NULL;
    long poses_wanted = 100;
    double stiffness = 0.25, timeout_s = 10.0;
    for (int i = 1; i < argc; i++) {
        if (i + 1 >= argc) usage();
        if (!strcmp(argv[i], "--pub")) pub = argv[++i];
        else if (!strcmp(argv[i], "--ctl")) ctl = argv[++i];
        else if (!strcmp(argv[i], "--keys")) keys = argv[++i];
        else if (!strcmp(argv[i], "--poses")) poses_wanted = atol(argv[++i]);
        else if (!strcmp(argv[i], "--stiffness")) stiffness = atof(argv[++i]);
        else if (!strcmp(argv[i], "--timeout")) timeout_s = atof(argv[++i]);
        else usage();
    }
    if (!pub || !ctl || poses_wanted <= 0 || !(stiffness > 0) || !(timeout_s > 0)) usage();
    int timeout_ms = (int)(timeout_s * 1000);

    void *ctx = zmq_ctx_new();
    void *sub = zmq_socket(ctx, ZMQ_SUB);
    void *req = zmq_socket(ctx, ZMQ_REQ);
    int zero = 0, hwm = 100000;
    zmq_setsockopt(sub, ZMQ_LINGER, &zero, sizeof zero);
    zmq_setsockopt(req, ZMQ_LINGER, &zero, sizeof zero);
    zmq_setsockopt(sub, ZMQ_RCVHWM, &hwm, sizeof hwm);
    zmq_setsockopt(sub, ZMQ_RCVTIMEO, &timeout_ms, sizeof timeout_ms);
    zmq_setsockopt(req, ZMQ_RCVTIMEO, &timeout_ms, sizeof timeout_ms);
    if (keys && (use_keys(sub, keys) || use_keys(req, keys))) return 1;
    zmq_setsockopt(sub, ZMQ_SUBSCRIBE, "pose", 4);
    zmq_setsockopt(sub, ZMQ_SUBSCRIBE, "scene", 5);
    if (zmq_connect(sub, pub) || zmq_connect(req, ctl)) {
        fprintf(stderr, "sasprobe_follow: cannot connect: %s\n", zmq_strerror(zmq_errno()));
        return 2;
    }

    static char reply[MAX_MESSAGE];
    char token[128], token2[128], json[256];
    if (request(req, "{\"version\":1,\"cmd\":\"status\",\"id\":\"c-status\"}", reply, sizeof reply)) {
        fprintf(stderr, "sasprobe_follow: no reply to status from %s within %g s\n", ctl, timeout_s);
        return 1;
    }
    if (expect_ok("status", reply, "c-status")) return 1;
    copy_token(json_value(reply, "rate_hz"), token, sizeof token); /* the loop's measured rate */
    copy_token(json_value(reply, "n_atoms"), token2, sizeof token2);
    printf("status rate_hz=%s n_atoms=%s\n", token, token2);

    snprintf(json, sizeof json,
             "{\"version\":1,\"cmd\":\"set\",\"args\":{\"stiffness_n_per_mm\":%.17g},\"id\":\"c-set\"}", stiffness);
    if (request(req, json, reply, sizeof reply) || expect_ok("set", reply, "c-set")) return 1;
    copy_token(json_value(reply, "seq"), token, sizeof token);
    copy_token(json_value(reply, "revision"), token2, sizeof token2);
    printf("set seq=%s revision=%s\n", token, token2);

    static unsigned char payload[MAX_MESSAGE];
    static char scene[MAX_MESSAGE + 1];
    char topic[32], why[128];
    long poses = 0, scenes = 0, lost = 0, last_revision = -1;
    uint64_t last_seq = 0;
    while (poses < poses_wanted) {
        int t = zmq_recv(sub, topic, sizeof topic - 1, 0);
        if (t < 0) {
            fprintf(stderr, "sasprobe_follow: nothing from %s within %g s\n", pub, timeout_s);
            return 1;
        }
        topic[t < (int)sizeof topic - 1 ? t : (int)sizeof topic - 1] = 0;
        int more = 0;
        size_t more_len = sizeof more;
        zmq_getsockopt(sub, ZMQ_RCVMORE, &more, &more_len);
        if (!more) { fprintf(stderr, "sasprobe_follow: a message of one frame\n"); return 1; }
        int n = zmq_recv(sub, payload, sizeof payload, 0);
        if (n < 0 || n > (int)sizeof payload) { fprintf(stderr, "sasprobe_follow: payload too large\n"); return 1; }
        if (!strcmp(topic, "pose")) {
            pose_t p;
            if (decode_pose(payload, (size_t)n, &p, why, sizeof why)) {
                fprintf(stderr, "sasprobe_follow: %s\n", why);
                return 1;
            }
            if (poses && p.seq > last_seq + 1) lost += (long)(p.seq - last_seq - 1);
            last_seq = p.seq;
            poses++;
            print_pose(&p);
        } else if (!strcmp(topic, "scene")) {
            memcpy(scene, payload, (size_t)n);
            scene[n] = 0;
            copy_token(json_value(scene, "revision"), token, sizeof token);
            long revision = atol(token);
            scenes++;
            if (revision != last_revision) { /* the scene is re-sent unchanged at least once a second */
                const char *structure = json_value(scene, "structure");
                copy_token(structure ? json_value(structure, "name") : NULL, token2, sizeof token2);
                copy_token(json_value(scene, "stiffness_n_per_mm"), token, sizeof token);
                printf("scene revision=%ld structure=%s stiffness_n_per_mm=%s\n", revision, token2, token);
                last_revision = revision;
            }
        }
    }
    printf("done poses=%ld lost=%ld scenes=%ld\n", poses, lost, scenes);
    zmq_close(sub);
    zmq_close(req);
    zmq_ctx_term(ctx);
    return 0;
}
