/*
 * A stand-in for the OpenHaptics HD library, for tests: the HDAPI entry points the
 * sasprobe driver calls, with the documented enum values, a 1 kHz scheduler thread,
 * calibration states, error reporting, and a stylus held by a spring "hand" so a
 * commanded force moves it. fake_* functions let the test steer it.
 *
 * Build: cc -shared -fPIC -O2 -o libHD.so fake_libhd.c -lpthread
 */
#include <math.h>
#include <pthread.h>
#include <stddef.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

typedef unsigned int HHD;
typedef unsigned int HDenum;
typedef unsigned int HDerror;
typedef unsigned int HDCallbackCode;
typedef unsigned long HDSchedulerHandle;
typedef HDCallbackCode (*HDSchedulerCallback)(void *);
typedef struct { HDerror errorCode; int internalErrorCode; HHD hHD; } HDErrorInfo;

#define HD_SUCCESS 0x0000
#define HD_INVALID_ENUM 0x0100
#define HD_EXCEEDED_MAX_FORCE 0x0201
#define HD_COMM_ERROR 0x0302
#define HD_COMM_CONFIG_ERROR 0x0303
#define HD_INVALID_HANDLE 0xFFFFFFFF
#define HD_CALLBACK_DONE 0
#define HD_CALLBACK_CONTINUE 1
#define HD_CALIBRATION_OK 0x5000
#define HD_CALIBRATION_NEEDS_UPDATE 0x5001
#define HD_CALIBRATION_NEEDS_MANUAL_INPUT 0x5002

static pthread_mutex_t lock = PTHREAD_MUTEX_INITIALIZER;
static pthread_t thread;
static volatile int running = 0;
static HDSchedulerCallback callback = NULL;
static void *callback_data = NULL;
static int initialised = 0, force_enabled = 0, in_frame = 0, unplugged = 0;
static HDerror pending_error = HD_SUCCESS, persistent_error = HD_SUCCESS;
static int calibration = HD_CALIBRATION_NEEDS_MANUAL_INPUT;
static double hand[3] = {0, 0, 0}, position[3] = {0, 0, 0}, velocity[3] = {0, 0, 0};
static double force[3] = {0, 0, 0}, max_force_seen = 0.0, yaw = 0.0;
static int buttons = 0;
static double sweep_mm = 0.0; /* the hand swings along x by this much (FAKE_HD_SWEEP), period 2 s */
static long callbacks_run = 0, forces_exceeding = 0;
static const double HAND_STIFFNESS = 0.5; /* N/mm */
static const double MAX_FORCE = 3.3;

static void set_error(HDerror code) { if (pending_error == HD_SUCCESS) pending_error = code; }

HHD hdInitDevice(const char *name) {
    pthread_mutex_lock(&lock);
    HHD h = 1;
    if (unplugged || (name && strcmp(name, "Default PHANToM") && strcmp(name, "Test Touch"))) {
        set_error(HD_COMM_CONFIG_ERROR);
        h = HD_INVALID_HANDLE;
    } else {
        initialised = 1;
        persistent_error = HD_SUCCESS;
        /* for tests in another process: FAKE_HD_CALIBRATED=1 skips the inkwell, FAKE_HD_HAND="x,y,z" */
        const char *cal = getenv("FAKE_HD_CALIBRATED"), *where = getenv("FAKE_HD_HAND");
        const char *sweep = getenv("FAKE_HD_SWEEP");
        if (cal && cal[0] == '1') calibration = HD_CALIBRATION_OK;
        if (where) sscanf(where, "%lf,%lf,%lf", &hand[0], &hand[1], &hand[2]);
        if (sweep) sweep_mm = atof(sweep);
    }
    pthread_mutex_unlock(&lock);
    return h;
}
void hdDisableDevice(HHD h) { (void)h; initialised = 0; force_enabled = 0; }
void hdMakeCurrentDevice(HHD h) { (void)h; }
HDErrorInfo hdGetError(void) {
    pthread_mutex_lock(&lock);
    HDErrorInfo e = {pending_error, (int)pending_error + 7, 1};
    pending_error = HD_SUCCESS;
    pthread_mutex_unlock(&lock);
    return e;
}
const char *hdGetErrorString(HDerror code) {
    switch (code) {
    case HD_COMM_ERROR: return "Communication error";
    case HD_COMM_CONFIG_ERROR: return "Device not found";
    default: return "Error";
    }
}
void hdEnable(HDenum cap) { if (cap == 0x4000) force_enabled = 1; }
void hdBeginFrame(HHD h) { (void)h; in_frame = 1; }
void hdEndFrame(HHD h) {
    (void)h;
    pthread_mutex_lock(&lock);
    in_frame = 0;
    if (persistent_error != HD_SUCCESS) set_error(persistent_error);
    /* the stylus settles where the hand's spring balances the motor force */
    double applied[3] = {0, 0, 0};
    if (force_enabled && persistent_error == HD_SUCCESS)
        for (int i = 0; i < 3; i++) applied[i] = force[i];
    double swing[3] = {sweep_mm * sin(2.0 * 3.14159265358979323846 * callbacks_run / 2000.0), 0, 0};
    for (int i = 0; i < 3; i++) {
        double p = hand[i] + swing[i] + applied[i] / HAND_STIFFNESS;
        velocity[i] = (p - position[i]) * 1000.0;
        position[i] = p;
    }
    pthread_mutex_unlock(&lock);
}
void hdGetDoublev(HDenum param, double *out) {
    pthread_mutex_lock(&lock);
    switch (param) {
    case 0x2050: memcpy(out, position, sizeof position); break;
    case 0x2051: memcpy(out, velocity, sizeof velocity); break;
    case 0x2052: { /* column-major 4x4: a yaw about Y, then the position */
        double c = cos(yaw), s = sin(yaw);
        double m[16] = {c, 0, -s, 0, 0, 1, 0, 0, s, 0, c, 0, position[0], position[1], position[2], 1};
        memcpy(out, m, sizeof m);
        break;
    }
    case 0x2551: { double box[6] = {-80, -60, -70, 80, 60, 0}; memcpy(out, box, sizeof box); break; }
    case 0x2602: out[0] = 0.5; break;
    case 0x2603: out[0] = MAX_FORCE; break;
    case 0x2604: out[0] = 0.88; break;
    case 0x2609: out[0] = 0.004; break;
    default: set_error(HD_INVALID_ENUM);
    }
    pthread_mutex_unlock(&lock);
}
void hdGetIntegerv(HDenum param, int *out) {
    pthread_mutex_lock(&lock);
    if (param == 0x2000) *out = buttons;
    else if (param == 0x2555) *out = 2 | 4; /* auto, inkwell */
    else set_error(HD_INVALID_ENUM);
    pthread_mutex_unlock(&lock);
}
const char *hdGetString(HDenum param) { return param == 0x2501 ? "Touch (emulated)" : ""; }
void hdSetDoublev(HDenum param, const double *in) {
    pthread_mutex_lock(&lock);
    if (param == 0x2700) {
        double norm = sqrt(in[0] * in[0] + in[1] * in[1] + in[2] * in[2]);
        if (norm > max_force_seen) max_force_seen = norm;
        if (norm > MAX_FORCE + 1e-9) { forces_exceeding++; set_error(HD_EXCEEDED_MAX_FORCE); }
        for (int i = 0; i < 3; i++) force[i] = (isfinite(norm) && norm <= MAX_FORCE) ? in[i] : 0.0;
    } else {
        set_error(HD_INVALID_ENUM);
    }
    pthread_mutex_unlock(&lock);
}
HDSchedulerHandle hdScheduleAsynchronous(HDSchedulerCallback cb, void *data, unsigned short priority) {
    (void)priority;
    callback = cb;
    callback_data = data;
    return 42;
}
static void *servo(void *arg) {
    (void)arg;
    struct timespec period = {0, 1000000};
    while (running) {
        HDSchedulerCallback cb = callback;
        if (cb) {
            callbacks_run++;
            if (cb(callback_data) == HD_CALLBACK_DONE) callback = NULL;
        }
        nanosleep(&period, NULL);
    }
    return NULL;
}
void hdStartScheduler(void) {
    if (!running) { running = 1; pthread_create(&thread, NULL, servo, NULL); }
}
void hdStopScheduler(void) {
    if (running) { running = 0; pthread_join(thread, NULL); }
}
void hdUnschedule(HDSchedulerHandle h) { (void)h; callback = NULL; }
unsigned int hdCheckCalibration(void) { return (unsigned int)calibration; }
void hdUpdateCalibration(unsigned int style) {
    if (calibration == HD_CALIBRATION_NEEDS_UPDATE && (style & (2 | 4))) calibration = HD_CALIBRATION_OK;
}

/* --- test controls ------------------------------------------------------------ */
void fake_set_hand(double x, double y, double z) { pthread_mutex_lock(&lock); hand[0] = x; hand[1] = y; hand[2] = z; pthread_mutex_unlock(&lock); }
void fake_set_buttons(int b) { buttons = b; }
void fake_set_yaw(double radians) { yaw = radians; }
void fake_put_in_inkwell(void) { if (calibration == HD_CALIBRATION_NEEDS_MANUAL_INPUT) calibration = HD_CALIBRATION_NEEDS_UPDATE; }
void fake_reset(void) {
    pthread_mutex_lock(&lock);
    sweep_mm = 0.0;
    calibration = HD_CALIBRATION_NEEDS_MANUAL_INPUT;
    unplugged = 0; persistent_error = HD_SUCCESS; pending_error = HD_SUCCESS;
    max_force_seen = 0; forces_exceeding = 0; callbacks_run = 0; buttons = 0; yaw = 0;
    for (int i = 0; i < 3; i++) { hand[i] = position[i] = velocity[i] = force[i] = 0; }
    pthread_mutex_unlock(&lock);
}
void fake_unplug(void) { pthread_mutex_lock(&lock); unplugged = 1; persistent_error = HD_COMM_ERROR; pthread_mutex_unlock(&lock); }
void fake_replug(void) { pthread_mutex_lock(&lock); unplugged = 0; pthread_mutex_unlock(&lock); }
void fake_force(double *out) { pthread_mutex_lock(&lock); memcpy(out, force, sizeof force); pthread_mutex_unlock(&lock); }
double fake_max_force_seen(void) { return max_force_seen; }
long fake_forces_exceeding(void) { return forces_exceeding; }
long fake_callbacks_run(void) { return callbacks_run; }
int fake_force_enabled(void) { return force_enabled; }
