/*
 * A stand-in for Force Dimension's DHD library (libdhd.so), for tests: the DHD entry points
 * a host calls, a handle held by a spring "hand" that the motors' force moves, per-thread
 * error codes, and a link that can fail.
 *
 * Written from the SDK's public C header dhdc.h (WPI-AIM/ambf @ 2d674b6e,
 * external/DHD/include/dhdc.h, SDK 3.7.0-pre; chai3d/chai3d @ 7c76b1f2,
 * externals/DHD/include/dhdc.h, SDK 3.17.5), the unit and return-value docstrings of
 * forcedimension-core 1.0.0 (PyPI), and CHAI3D's use of the library
 * (src/devices/CDeltaDevices.cpp). Behaviour modelled:
 * - every device call ends in `char ID`, the value dhdOpenID returned (-1: the device
 *   opened last); it returns >= 0 on success, -1 on error, the code then in the calling
 *   thread's dhdErrorGetLast() (a thread-local here, as the SDK says "in the running thread");
 * - positions in metres in DHD's frame (x toward the user, y right, z up), origin at the
 *   workspace centre; forces in newtons in the same frame;
 * - the motors render nothing until dhdEnableForce(DHD_ON); dhdSetForce beyond the
 *   motors' limit renders the limit, direction kept, and returns DHD_MOTOR_SATURATED (2);
 * - dhdGetPosition returns DHD_TIMEGUARD (1), a success, on every n-th call (the cached
 *   position, as a device polled faster than its TimeGuard answers);
 * - dhdGetLinearVelocity fails with DHD_ERROR_TIMEOUT unless two positions were read in
 *   the last DHD_VELOCITY_WINDOW (20 ms);
 * - a link that goes down (cable out, a device that no longer answers): every call fails
 *   with DHD_ERROR_COM (or the code the test chose), the device leaves the count, and
 *   its motors turn off (DHD_FORCE_OFF_USBDISCN); force must be enabled again after.
 * Not modelled: the real error strings, expert mode, gravity compensation, the gripper.
 *
 * The test side steers the device through a control block (struct control) in a shared
 * file named by FAKE_DHD_CONTROL, read at the first call, so a daemon in another process
 * and a test in this one see the same device. A physics thread integrates the handle
 * every half millisecond from the first dhdOpenID on.
 *
 * Build: cc -shared -fPIC -O2 -o libdhd.so fake_libdhd.c -lpthread -lm
 * (-DFAKE_DHD_WITHOUT_SET_FORCE leaves dhdSetForce out: a library that lacks a symbol)
 */
#include <fcntl.h>
#include <math.h>
#include <pthread.h>
#include <sched.h>
#include <stdbool.h>
#include <stdint.h>
#include <stdlib.h>
#include <string.h>
#include <sys/mman.h>
#include <sys/stat.h>
#include <time.h>
#include <unistd.h>

/* dhdc.h: enum dhd_errors (values in order), return values, status */
#define DHD_NO_ERROR 0
#define DHD_ERROR_COM 2
#define DHD_ERROR_NO_DEVICE_FOUND 5
#define DHD_ERROR_TIMEOUT 7
#define DHD_ERROR_INVALID_INDEX 15
#define DHD_ON 1
#define DHD_TIMEGUARD 1
#define DHD_MOTOR_SATURATED 2
#define DHD_MAX_STATUS 17
#define DHD_STATUS_POWER 0
#define DHD_STATUS_CONNECTED 1
#define DHD_STATUS_FORCE 5
#define DHD_VELOCITY_WINDOW_S 0.020
/* dhdc.h: device types */
#define DHD_DEVICE_DELTA3 63
#define DHD_DEVICE_OMEGA3 33
#define DHD_DEVICE_OMEGA6_RIGHT 34
#define DHD_DEVICE_OMEGA7_RIGHT 35
#define DHD_DEVICE_OMEGA6_LEFT 36
#define DHD_DEVICE_OMEGA7_LEFT 37
#define DHD_DEVICE_SIGMA7_RIGHT 104
#define DHD_DEVICE_SIGMA7_LEFT 105
#define DHD_DEVICE_FALCON 60

#define MAX_DEVICES 4
static const double MASS = 0.1;                /* kg: the handle and the hand's grip on it */
static const double DEFAULT_HAND_K = 500.0;    /* N/m: the spring of the hand */
static const double DEFAULT_HAND_SPEED = 0.4;  /* m/s: how fast the hand moves to its target */
static const double DEFAULT_MOTOR_LIMIT = 12.0; /* N: what the motors can render (ours) */
static const double SUBSTEP_S = 0.00025;

/* The control block: the first part the test writes, the second the library. */
struct control {
    double hand[3];              /* where the hand wants the handle, DHD frame, m */
    double hand_speed;           /* m/s (0: DEFAULT_HAND_SPEED) */
    double hand_stiffness;       /* N/m (0: DEFAULT_HAND_K) */
    double motor_limit;          /* N (0: DEFAULT_MOTOR_LIMIT) */
    double wrist_angle;          /* the wrist's rotation about z (up), rad */
    int32_t count;               /* devices the SDK sees while the link is up */
    int32_t types[MAX_DEVICES];  /* dhdGetSystemType per index */
    int32_t serials[MAX_DEVICES];
    int32_t buttons;
    int32_t link_down;           /* nonzero: every call fails with link_error, motors off */
    int32_t link_error;          /* 0: DHD_ERROR_COM */
    int32_t timeguard_every;     /* every n-th dhdGetPosition answers DHD_TIMEGUARD (0: never) */
    /* written by the library */
    double handle[3];            /* where the handle is, DHD frame, m */
    double velocity[3];          /* m/s */
    double force[3];             /* what the motors render now, N */
    double max_force;            /* the largest force rendered */
    int64_t position_reads;
    int64_t timeguards;
    int64_t set_force_calls;
    int64_t saturated;
    int64_t failed_calls;
    int64_t steps;
    int32_t open_id;             /* -1: nothing open */
    int32_t opens;
    int32_t force_enabled;
    int32_t enables;             /* dhdEnableForce(DHD_ON) calls that took */
    int32_t forces_ignored;      /* nonzero dhdSetForce while force output was off */
    int32_t pad;
};

static struct control fallback = {.count = 1, .types = {DHD_DEVICE_OMEGA3}, .open_id = -1};
static struct control *volatile ctl = &fallback;
static char ctl_path[4096];
/* The daemon's loop calls in at a real-time priority; the physics thread runs at normal
   priority (dhdOpenID). The lock inherits priority, so a busy machine cannot park the loop
   behind a physics thread preempted while holding it: a real arm's physics runs on its own
   hardware, outside the host's scheduler. */
static pthread_mutex_t lock;
__attribute__((constructor)) static void init_lock(void) {
    pthread_mutexattr_t a;
    pthread_mutexattr_init(&a);
    pthread_mutexattr_setprotocol(&a, PTHREAD_PRIO_INHERIT);
    pthread_mutex_init(&lock, &a);
    pthread_mutexattr_destroy(&a);
}
static pthread_t physics;
static int physics_running = 0;
static double hand_now[3], commanded[3], last_step_s = -1.0;
static double reads_at[2] = {-1.0, -1.0}; /* the last two dhdGetPosition times */
static __thread int last_error = DHD_NO_ERROR;

static double now_s(void) {
    struct timespec t;
    clock_gettime(CLOCK_MONOTONIC, &t);
    return (double)t.tv_sec + 1e-9 * (double)t.tv_nsec;
}

/* Under the lock: map the control file FAKE_DHD_CONTROL names; a new file is a new device
   (its handle starts where its hand is). */
static void map_control(void) {
    const char *path = getenv("FAKE_DHD_CONTROL");
    if (!path || !path[0]) return;
    if (strcmp(path, ctl_path) == 0) return;
    int fd = open(path, O_RDWR);
    struct stat st;
    if (fd < 0 || fstat(fd, &st) != 0 || st.st_size < (off_t)sizeof(struct control)) {
        if (fd >= 0) close(fd);
        return;
    }
    void *m = mmap(NULL, sizeof(struct control), PROT_READ | PROT_WRITE, MAP_SHARED, fd, 0);
    close(fd);
    if (m == MAP_FAILED) return;
    ctl = (struct control *)m;
    strncpy(ctl_path, path, sizeof ctl_path - 1);
    memcpy(ctl->handle, ctl->hand, sizeof ctl->handle);
    memcpy(hand_now, ctl->hand, sizeof hand_now);
    memset(commanded, 0, sizeof commanded);
    last_step_s = reads_at[0] = reads_at[1] = -1.0;
}

static int fail(int code) {
    last_error = code;
    ctl->failed_calls++;
    return -1;
}

static void motors_off(void) {
    ctl->force_enabled = 0;
    memset(commanded, 0, sizeof commanded);
    memset(ctl->force, 0, sizeof ctl->force);
}

/* The hand moves toward its target; the handle is a mass held by the hand's spring
   (critically damped) and pushed by the motors. */
static void step_to(double t) {
    if (last_step_s < 0) {
        last_step_s = t;
        return;
    }
    double dt = t - last_step_s;
    if (dt > 1.0) dt = 1.0;
    last_step_s = t;
    double k = ctl->hand_stiffness > 0 ? ctl->hand_stiffness : DEFAULT_HAND_K;
    double speed = ctl->hand_speed > 0 ? ctl->hand_speed : DEFAULT_HAND_SPEED;
    double c = 2.0 * sqrt(k * MASS);
    int n = (int)ceil(dt / SUBSTEP_S);
    if (n < 1) return;
    double h = dt / n;
    for (int s = 0; s < n; s++) {
        double d[3], dist = 0;
        for (int i = 0; i < 3; i++) { d[i] = ctl->hand[i] - hand_now[i]; dist += d[i] * d[i]; }
        dist = sqrt(dist);
        double reach = speed * h, f = dist <= reach || dist == 0 ? 1.0 : reach / dist;
        for (int i = 0; i < 3; i++) {
            hand_now[i] += d[i] * f;
            double total = ctl->force[i] + k * (hand_now[i] - ctl->handle[i]) - c * ctl->velocity[i];
            ctl->velocity[i] += h * total / MASS;
            ctl->handle[i] += h * ctl->velocity[i];
        }
    }
    ctl->steps++;
}

static void *run_physics(void *arg) {
    (void)arg;
    struct timespec half_ms = {0, 500000};
    for (;;) {
        pthread_mutex_lock(&lock);
        step_to(now_s());
        pthread_mutex_unlock(&lock);
        nanosleep(&half_ms, NULL);
    }
    return NULL;
}

/* Under the lock: the device an ID names, or -1 with the error set. */
static int device(char id) {
    map_control();
    if (ctl->link_down) {
        motors_off();
        return fail(ctl->link_error ? ctl->link_error : DHD_ERROR_COM);
    }
    if (ctl->open_id < 0 || (id != -1 && id != ctl->open_id)) return fail(DHD_ERROR_INVALID_INDEX);
    return ctl->open_id;
}

static bool has_wrist(int type) {
    return type == DHD_DEVICE_OMEGA6_RIGHT || type == DHD_DEVICE_OMEGA6_LEFT || type == DHD_DEVICE_OMEGA7_RIGHT ||
           type == DHD_DEVICE_OMEGA7_LEFT || type == DHD_DEVICE_SIGMA7_RIGHT || type == DHD_DEVICE_SIGMA7_LEFT;
}

/* error reporting */
int dhdErrorGetLast(void) { return last_error; }
const char *dhdErrorGetStr(int error) {
    switch (error) {
    case DHD_NO_ERROR: return "no error";
    case DHD_ERROR_COM: return "communication error";
    case DHD_ERROR_NO_DEVICE_FOUND: return "no device found";
    case DHD_ERROR_TIMEOUT: return "timeout";
    default: return "error";
    }
}
const char *dhdErrorGetLastStr(void) { return dhdErrorGetStr(last_error); }

/* standard SDK */
int dhdGetDeviceCount(void) {
    pthread_mutex_lock(&lock);
    map_control();
    int n = ctl->link_down ? (ctl->count > 0 ? ctl->count - 1 : 0) : ctl->count;
    pthread_mutex_unlock(&lock);
    return n;
}
int dhdOpenID(char index) {
    pthread_mutex_lock(&lock);
    map_control();
    int r;
    if (ctl->link_down) r = fail(DHD_ERROR_NO_DEVICE_FOUND);
    else if (index < 0 || index >= ctl->count || index >= MAX_DEVICES) r = fail(DHD_ERROR_INVALID_INDEX);
    else {
        r = ctl->open_id = index;
        ctl->opens++;
        motors_off();
        if (!physics_running) {
            physics_running = 1;
            /* At normal priority whatever the caller's: a real arm's physics takes no host
               time from the loop (the lock above lifts it while the loop waits on it). */
            pthread_attr_t attr;
            struct sched_param normal = {0};
            pthread_attr_init(&attr);
            pthread_attr_setinheritsched(&attr, PTHREAD_EXPLICIT_SCHED);
            pthread_attr_setschedpolicy(&attr, SCHED_OTHER);
            pthread_attr_setschedparam(&attr, &normal);
            pthread_create(&physics, &attr, run_physics, NULL);
            pthread_attr_destroy(&attr);
        }
    }
    pthread_mutex_unlock(&lock);
    return r;
}
int dhdClose(char id) {
    pthread_mutex_lock(&lock);
    int r = device(id);
    if (r >= 0) {
        motors_off();
        ctl->open_id = -1;
        r = 0;
    }
    pthread_mutex_unlock(&lock);
    return r;
}
int dhdGetSystemType(char id) {
    pthread_mutex_lock(&lock);
    int r = device(id);
    if (r >= 0) r = ctl->types[r];
    pthread_mutex_unlock(&lock);
    return r;
}
const char *dhdGetSystemName(char id) {
    pthread_mutex_lock(&lock);
    int r = device(id), type = r >= 0 ? ctl->types[r] : -1;
    pthread_mutex_unlock(&lock);
    switch (type) {
    case DHD_DEVICE_DELTA3: return "delta.3";
    case DHD_DEVICE_OMEGA3: return "omega.3";
    case DHD_DEVICE_OMEGA6_RIGHT: case DHD_DEVICE_OMEGA6_LEFT: return "omega.6";
    case DHD_DEVICE_OMEGA7_RIGHT: case DHD_DEVICE_OMEGA7_LEFT: return "omega.7";
    case DHD_DEVICE_SIGMA7_RIGHT: case DHD_DEVICE_SIGMA7_LEFT: return "sigma.7";
    case DHD_DEVICE_FALCON: return "Falcon";
    case -1: return NULL;
    default: return "unknown";
    }
}
int dhdGetSerialNumber(unsigned short *sn, char id) {
    pthread_mutex_lock(&lock);
    int r = device(id);
    if (r >= 0) { *sn = (unsigned short)ctl->serials[r]; r = 0; }
    pthread_mutex_unlock(&lock);
    return r;
}
int dhdGetStatus(int status[DHD_MAX_STATUS], char id) {
    pthread_mutex_lock(&lock);
    int r = device(id);
    if (r >= 0) {
        memset(status, 0, sizeof(int) * DHD_MAX_STATUS);
        status[DHD_STATUS_POWER] = status[DHD_STATUS_CONNECTED] = 1;
        status[DHD_STATUS_FORCE] = ctl->force_enabled;
        r = 0;
    }
    pthread_mutex_unlock(&lock);
    return r;
}
int dhdEnableForce(unsigned char val, char id) {
    pthread_mutex_lock(&lock);
    int r = device(id);
    if (r >= 0) {
        if (val == DHD_ON) { ctl->force_enabled = 1; ctl->enables++; } else motors_off();
        r = 0;
    }
    pthread_mutex_unlock(&lock);
    return r;
}
bool dhdHasWrist(char id) {
    pthread_mutex_lock(&lock);
    int r = device(id);
    bool wrist = r >= 0 && has_wrist(ctl->types[r]);
    pthread_mutex_unlock(&lock);
    return wrist;
}
unsigned int dhdGetButtonMask(char id) {
    pthread_mutex_lock(&lock);
    int r = device(id);
    unsigned int mask = r >= 0 ? (unsigned int)ctl->buttons : 0u;
    pthread_mutex_unlock(&lock);
    return mask;
}
int dhdGetPosition(double *px, double *py, double *pz, char id) {
    pthread_mutex_lock(&lock);
    int r = device(id);
    if (r >= 0) {
        double t = now_s();
        step_to(t);
        *px = ctl->handle[0];
        *py = ctl->handle[1];
        *pz = ctl->handle[2];
        reads_at[0] = reads_at[1];
        reads_at[1] = t;
        ctl->position_reads++;
        r = 0;
        if (ctl->timeguard_every > 0 && ctl->position_reads % ctl->timeguard_every == 0) {
            r = DHD_TIMEGUARD;
            ctl->timeguards++;
        }
    }
    pthread_mutex_unlock(&lock);
    return r;
}
int dhdGetLinearVelocity(double *vx, double *vy, double *vz, char id) {
    pthread_mutex_lock(&lock);
    int r = device(id);
    if (r >= 0) {
        if (reads_at[0] < 0 || now_s() - reads_at[0] > DHD_VELOCITY_WINDOW_S) {
            r = fail(DHD_ERROR_TIMEOUT);
        } else {
            *vx = ctl->velocity[0];
            *vy = ctl->velocity[1];
            *vz = ctl->velocity[2];
            r = 0;
        }
    }
    pthread_mutex_unlock(&lock);
    return r;
}
int dhdGetOrientationFrame(double matrix[3][3], char id) {
    pthread_mutex_lock(&lock);
    int r = device(id);
    if (r >= 0) { /* identity for an arm without a wrist (forcedimension-core's getOrientationFrame) */
        double a = has_wrist(ctl->types[r]) ? ctl->wrist_angle : 0.0, c = cos(a), s = sin(a);
        double m[3][3] = {{c, -s, 0}, {s, c, 0}, {0, 0, 1}};
        memcpy(matrix, m, sizeof m);
        r = 0;
    }
    pthread_mutex_unlock(&lock);
    return r;
}
#ifndef FAKE_DHD_WITHOUT_SET_FORCE
int dhdSetForce(double fx, double fy, double fz, char id) {
    pthread_mutex_lock(&lock);
    int r = device(id);
    if (r >= 0) {
        double f[3] = {fx, fy, fz}, norm = sqrt(fx * fx + fy * fy + fz * fz);
        double limit = ctl->motor_limit > 0 ? ctl->motor_limit : DEFAULT_MOTOR_LIMIT, scale = 1.0;
        r = 0;
        ctl->set_force_calls++;
        if (!isfinite(norm)) { scale = 0.0; norm = 0.0; }
        if (norm > limit + 1e-9) { scale = limit / norm; r = DHD_MOTOR_SATURATED; ctl->saturated++; }
        step_to(now_s()); /* the old force acted until now */
        if (!ctl->force_enabled) {
            if (norm > 0) ctl->forces_ignored++;
            memset(ctl->force, 0, sizeof ctl->force);
        } else {
            for (int i = 0; i < 3; i++) ctl->force[i] = commanded[i] = scale == 0.0 ? 0.0 : f[i] * scale;
            double n = norm * scale;
            if (n > ctl->max_force) ctl->max_force = n;
        }
    }
    pthread_mutex_unlock(&lock);
    return r;
}
#endif

/* for the test side: the size of struct control, to check its layout */
size_t fake_control_size(void) { return sizeof(struct control); }
