/*
 * A stand-in for the OpenHaptics HD library (libHD.so), for tests: the HDAPI entry points
 * a host calls, a 1 kHz scheduler thread, the SDK's calibration styles and error stack,
 * and a stylus held by a spring "hand" so a commanded force moves it.
 *
 * Written from the public HDAPI headers and examples (danepowell/openhaptics, commit
 * 2ce9a4830bd920eccfe3ca5d765fb7bdfd1ae253, usr/include/HD/hdDefines.h, hdDevice.h,
 * hdScheduler.h, HDU/hduError.h; usr/share/3DTouch/examples/HD/console/Calibration.c,
 * AnchoredSpringForce.c, ErrorHandling.c). Behaviour modelled:
 * - hdGetError pops an error stack, most recent first (hdDevice.h);
 * - calibration (Calibration.c): ENCODER_RESET zeroes the encoders wherever the arm is
 *   when hdUpdateCalibration is called (right only at the reset pose, all links
 *   orthogonal: here the origin); INKWELL needs the stylus in the inkwell
 *   (NEEDS_MANUAL_INPUT until then, NEEDS_UPDATE in it); AUTO needs only an update.
 *   Until calibrated the reported position is off by UNCALIBRATED_OFFSET. A device that
 *   loses power (unplugged) loses its calibration.
 * - HD_MAX_FORCE_CLAMPING is on by default (ErrorHandling.c turns it off "to make it
 *   easier to trigger device errors"): a force above the nominal maximum is clamped.
 * - a frame without hdSetDoublev(HD_CURRENT_FORCE) keeps rendering the last force
 *   (AnchoredSpringForce.c: "or else it will just continue rendering the last force"),
 *   and so do the motors when no frame runs at all (a callback that ended): the
 *   pessimistic reading, where the Programmer's Guide (p. 5-7) zeroes the force at each
 *   frame's start;
 * - an unplugged device: HD_COMM_ERROR every frame and from hdInitDevice, motors off;
 *   an HD_COMM_ERROR raised by the test (inject) leaves the device powered;
 * - hdDisable(HD_FORCE_OUTPUT) turns the motors off at once, no frame needed
 *   (OpenHaptics_Ref.pdf Table A-10: "All motors are turned on or off");
 * - whether the scheduler calls a callback again after a frame that raised a scheduler
 *   error is not said: by default it does, and a test may say it does not
 *   (`stop_calls_on_error`), so that nothing a host does after the error can help;
 * - a record for the test: the largest change of the rendered force from one frame to
 *   the next (`max_step`: a kick shows as a large step);
 * - the models (struct model): the names the library reports and the peak force,
 *   stiffness and damping of each (chai3d/chai3d 7c76b1f, src/devices/CPhantomDevices.cpp
 *   l. 495-590; the continuous force is ours),
 *   the usable box the size of the maker's nominal workspace (Desktop 160 x 120 x 120 mm,
 *   Premium 1.5 381 x 267 x 191 mm; where it lies in the library frame is ours), the
 *   serial number HD_DEVICE_SERIAL_NUMBER serves (the test's).
 * Not modelled: the real error strings, devices beyond one, synchronous callbacks.
 *
 * The test side steers the device through a control block (struct control) in a shared
 * file named by FAKE_HD_CONTROL, read at hdInitDevice, so a daemon in another process
 * and a test in this one see the same device. A new control file is a new device.
 *
 * Build: cc -shared -fPIC -O2 -o libHD.so fake_libhd.c -lpthread -lm
 */
#include <fcntl.h>
#include <math.h>
#include <pthread.h>
#include <stdint.h>
#include <stdlib.h>
#include <string.h>
#include <sys/mman.h>
#include <sys/stat.h>
#include <time.h>
#include <unistd.h>

/* hdDefines.h: types */
typedef unsigned int HHD;
typedef unsigned int HDenum;
typedef unsigned int HDerror;
typedef unsigned int HDCallbackCode;
typedef unsigned long HDSchedulerHandle;
typedef unsigned short HDushort;
typedef HDCallbackCode (*HDSchedulerCallback)(void *);
typedef struct { HDerror errorCode; int internalErrorCode; HHD hHD; } HDErrorInfo;

/* hdDefines.h: error codes */
#define HD_SUCCESS 0x0000
#define HD_INVALID_ENUM 0x0100
#define HD_INVALID_VALUE 0x0101
#define HD_EXCEEDED_MAX_FORCE 0x0201
#define HD_EXCEEDED_MAX_FORCE_IMPULSE 0x0202
#define HD_ILLEGAL_BEGIN 0x0400
#define HD_ILLEGAL_END 0x0401
#define HD_COMM_ERROR 0x0302
#define HD_COMM_CONFIG_ERROR 0x0303
/* hdDefines.h: parameters */
#define HD_CURRENT_BUTTONS 0x2000
#define HD_CURRENT_INKWELL_SWITCH 0x2002
#define HD_CURRENT_POSITION 0x2050
#define HD_CURRENT_VELOCITY 0x2051
#define HD_CURRENT_TRANSFORM 0x2052
#define HD_DEVICE_MODEL_TYPE 0x2501
#define HD_DEVICE_SERIAL_NUMBER 0x2504
#define HD_USABLE_WORKSPACE_DIMENSIONS 0x2551
#define HD_CALIBRATION_STYLE 0x2555
#define HD_NOMINAL_MAX_STIFFNESS 0x2602
#define HD_NOMINAL_MAX_FORCE 0x2603
#define HD_NOMINAL_MAX_CONTINUOUS_FORCE 0x2604
#define HD_NOMINAL_MAX_DAMPING 0x2609
#define HD_CURRENT_FORCE 0x2700
#define HD_FORCE_OUTPUT 0x4000
/* hdDefines.h: scheduler, calibration, handles */
#define HD_CALLBACK_DONE 0
#define HD_CALLBACK_CONTINUE 1
#define HD_CALIBRATION_OK 0x5000
#define HD_CALIBRATION_NEEDS_UPDATE 0x5001
#define HD_CALIBRATION_NEEDS_MANUAL_INPUT 0x5002
#define HD_CALIBRATION_ENCODER_RESET (1 << 0)
#define HD_CALIBRATION_AUTO (1 << 1)
#define HD_CALIBRATION_INKWELL (1 << 2)
#define HD_INVALID_HANDLE 0xFFFFFFFF

/* The emulated models (N, N/mm, N.s/mm, mm). Model 0 is an Omni-class arm with our numbers. */
struct model {
    const char *name;
    double max_force, max_continuous_force, max_stiffness, max_damping;
    double usable_box[6]; /* minX, minY, minZ, maxX, maxY, maxZ */
};
static const struct model MODELS[] = {
    {"Touch (emulated)", 3.3, 0.88, 0.5, 0.004, {-80, -60, -70, 80, 60, 0}},
    {"PHANTOM Desktop", 7.9, 1.75, 1.0, 0.005, {-80, -50, -100, 80, 70, 20}},
    {"PHANTOM Premium 1.5 6DOF", 8.5, 1.4, 0.8, 0.005, {-190.5, -100, -160, 190.5, 167, 31}},
};
#define N_MODELS ((int)(sizeof MODELS / sizeof MODELS[0]))
static const double HAND_STIFFNESS = 0.5; /* N/mm: the spring of the hand holding the stylus */
static const double UNCALIBRATED_OFFSET[3] = {3.0, -4.0, 5.0}; /* mm: how far off uncalibrated encoders read */

/* The control block: the first part the test writes, the second the library. */
struct control {
    double hand[3];              /* where the hand holds the stylus, library frame, mm */
    double yaw;                  /* gimbal yaw about y, rad */
    int32_t buttons;
    int32_t inkwell;             /* the stylus sits in the inkwell */
    int32_t plugged;             /* 0: the cable is out */
    int32_t styles;              /* calibration styles the device supports (read at hdInitDevice) */
    int32_t inject_code;         /* an HD error code to raise at the end of the next frames */
    int32_t inject_frames;       /* ... this many of them */
    int32_t model;               /* an index into MODELS */
    char serial[32];             /* what HD_DEVICE_SERIAL_NUMBER reads */
    /* written by the library */
    double force[3];             /* the force the motors render now, N */
    double max_force;
    double reset_distance_mm;    /* how far from the reset pose the arm was at the last encoder reset */
    int64_t frames;
    int64_t forces_clamped;
    int32_t force_enabled;
    int32_t scheduler_running;
    int32_t resets;              /* hdUpdateCalibration(HD_CALIBRATION_ENCODER_RESET) calls */
    int32_t resets_while_running;
    int32_t last_update_style;   /* the style of the last hdUpdateCalibration */
    int32_t calibration;         /* what hdCheckCalibration answers now */
    int32_t initialised;
    int32_t callback_done;       /* the servo callback returned HD_CALLBACK_DONE */
    double max_step;             /* the largest change of the rendered force from one frame to the next, N */
    int32_t stop_calls_on_error; /* test: 1 = after a frame that raised a scheduler error, no callback is called */
    int32_t halted;              /* the scheduler stopped calling callbacks (stop_calls_on_error) */
};

static struct control fallback = {.plugged = 1, .styles = HD_CALIBRATION_INKWELL};
static struct control *volatile ctl = &fallback;
static char ctl_path[4096];

static pthread_mutex_t lock = PTHREAD_MUTEX_INITIALIZER;
static pthread_t thread;
static volatile int running = 0;
static HDSchedulerCallback callback = NULL;
static void *callback_data = NULL;
static int in_frame = 0, calibrated = 0, offset_ready = 0;
static double offset[3], position[3], velocity[3], commanded[3];
static volatile int raised_scheduler_error = 0; /* in the callback now running */

#define STACK 16
static HDErrorInfo errors[STACK];
static int n_errors = 0;

static const struct model *current_model(void) {
    int m = ctl->model;
    return &MODELS[m >= 0 && m < N_MODELS ? m : 0];
}

/* hduError.o's hduIsSchedulerError: communication and timer errors */
static int is_scheduler_error(HDerror code) {
    return (code >= 0x0302 && code <= 0x0304) || code == 0x0500 || code == 0x0501;
}

static void push_error(HDerror code) {
    if (is_scheduler_error(code)) raised_scheduler_error = 1;
    if (n_errors == STACK) { memmove(errors, errors + 1, sizeof errors[0] * (STACK - 1)); n_errors--; }
    errors[n_errors].errorCode = code;
    errors[n_errors].internalErrorCode = (int)code + 7;
    errors[n_errors].hHD = 1;
    n_errors++;
}

/* What the motors render from now on (under the lock). */
static void render(const double applied[3]) {
    double step = 0.0;
    for (int i = 0; i < 3; i++) step += (applied[i] - ctl->force[i]) * (applied[i] - ctl->force[i]);
    if (sqrt(step) > ctl->max_step) ctl->max_step = sqrt(step);
    memcpy(ctl->force, applied, sizeof ctl->force);
    double norm = sqrt(applied[0] * applied[0] + applied[1] * applied[1] + applied[2] * applied[2]);
    if (norm > ctl->max_force) ctl->max_force = norm;
}

static void lose_calibration(void) {
    calibrated = 0;
    memcpy(offset, UNCALIBRATED_OFFSET, sizeof offset);
}

static int calibration_state(void) {
    if (calibrated) return HD_CALIBRATION_OK;
    if ((ctl->styles & HD_CALIBRATION_INKWELL) && !ctl->inkwell && !(ctl->styles & HD_CALIBRATION_AUTO))
        return HD_CALIBRATION_NEEDS_MANUAL_INPUT;
    if (ctl->styles & (HD_CALIBRATION_AUTO | HD_CALIBRATION_INKWELL)) return HD_CALIBRATION_NEEDS_UPDATE;
    return HD_CALIBRATION_NEEDS_MANUAL_INPUT; /* encoder reset only: the user must act */
}

static void map_control(void) {
    const char *path = getenv("FAKE_HD_CONTROL");
    if (!path || !path[0]) { ctl = &fallback; ctl_path[0] = 0; return; }
    if (strcmp(path, ctl_path) == 0) return; /* the same device as before */
    int fd = open(path, O_RDWR);
    struct stat st;
    if (fd < 0 || fstat(fd, &st) != 0 || st.st_size < (off_t)sizeof(struct control)) {
        if (fd >= 0) close(fd);
        ctl = &fallback;
        return;
    }
    void *m = mmap(NULL, sizeof(struct control), PROT_READ | PROT_WRITE, MAP_SHARED, fd, 0);
    close(fd);
    if (m == MAP_FAILED) { ctl = &fallback; return; }
    ctl = (struct control *)m;
    strncpy(ctl_path, path, sizeof ctl_path - 1);
    lose_calibration(); /* a new device: never calibrated yet */
}

/* hdDevice.h */
HHD hdInitDevice(const char *name) {
    pthread_mutex_lock(&lock);
    if (!offset_ready) { lose_calibration(); offset_ready = 1; }
    map_control();
    HHD h = 1;
    if (!ctl->plugged) {
        lose_calibration();
        push_error(HD_COMM_ERROR);
        h = HD_INVALID_HANDLE;
    } else if (name && strcmp(name, "Default PHANToM") && strcmp(name, "Test Touch")) {
        push_error(HD_COMM_CONFIG_ERROR);
        h = HD_INVALID_HANDLE;
    } else {
        ctl->initialised = 1;
        ctl->callback_done = 0;
        ctl->calibration = calibration_state();
    }
    pthread_mutex_unlock(&lock);
    return h;
}
void hdDisableDevice(HHD h) {
    (void)h;
    pthread_mutex_lock(&lock);
    ctl->initialised = 0;
    ctl->force_enabled = 0;
    memset(ctl->force, 0, sizeof ctl->force);
    pthread_mutex_unlock(&lock);
}
void hdMakeCurrentDevice(HHD h) { (void)h; }
HHD hdGetCurrentDevice(void) { return 1; }
HDErrorInfo hdGetError(void) {
    pthread_mutex_lock(&lock);
    HDErrorInfo e = {HD_SUCCESS, 0, 1};
    if (n_errors > 0) e = errors[--n_errors];
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
void hdEnable(HDenum cap) {
    pthread_mutex_lock(&lock);
    if (cap == HD_FORCE_OUTPUT) ctl->force_enabled = 1; else push_error(HD_INVALID_ENUM);
    pthread_mutex_unlock(&lock);
}
void hdDisable(HDenum cap) {
    pthread_mutex_lock(&lock);
    if (cap == HD_FORCE_OUTPUT) { /* Reference Table A-10: "All motors are turned on or off" */
        static const double off[3] = {0, 0, 0};
        ctl->force_enabled = 0;
        render(off);
    } else {
        push_error(HD_INVALID_ENUM);
    }
    pthread_mutex_unlock(&lock);
}
void hdBeginFrame(HHD h) {
    (void)h;
    pthread_mutex_lock(&lock);
    if (in_frame) push_error(HD_ILLEGAL_BEGIN);
    in_frame = 1;
    if (!ctl->plugged) lose_calibration();
    /* hdDevice.h: a frame's state is sampled as it begins. The stylus sits where the hand's
       spring balances the force the motors rendered since the last frame (header: "Begin grabs
       state information from the device. End sends information such as forces"). */
    for (int i = 0; i < 3; i++) {
        double p = ctl->hand[i] + ctl->force[i] / HAND_STIFFNESS - offset[i];
        velocity[i] = (p - position[i]) * 1000.0;
        position[i] = p;
    }
    pthread_mutex_unlock(&lock);
}
void hdEndFrame(HHD h) {
    (void)h;
    pthread_mutex_lock(&lock);
    if (!in_frame) push_error(HD_ILLEGAL_END);
    in_frame = 0;
    ctl->frames++;
    double applied[3] = {0, 0, 0};
    if (!ctl->plugged) {
        push_error(HD_COMM_ERROR);
    } else if (ctl->force_enabled) {
        memcpy(applied, commanded, sizeof applied); /* the last force sent, this frame or before */
    }
    if (ctl->inject_frames > 0) { ctl->inject_frames--; push_error((HDerror)ctl->inject_code); }
    render(applied);
    ctl->calibration = calibration_state();
    pthread_mutex_unlock(&lock);
}
void hdGetDoublev(HDenum param, double *out) {
    pthread_mutex_lock(&lock);
    switch (param) {
    case HD_CURRENT_POSITION: memcpy(out, position, sizeof position); break;
    case HD_CURRENT_VELOCITY: memcpy(out, velocity, sizeof velocity); break;
    case HD_CURRENT_TRANSFORM: { /* column-major 4x4: a yaw about y, then the position */
        double c = cos(ctl->yaw), s = sin(ctl->yaw);
        double m[16] = {c, 0, -s, 0, 0, 1, 0, 0, s, 0, c, 0, position[0], position[1], position[2], 1};
        memcpy(out, m, sizeof m);
        break;
    }
    case HD_USABLE_WORKSPACE_DIMENSIONS: memcpy(out, current_model()->usable_box, 6 * sizeof(double)); break;
    case HD_NOMINAL_MAX_STIFFNESS: out[0] = current_model()->max_stiffness; break;
    case HD_NOMINAL_MAX_FORCE: out[0] = current_model()->max_force; break;
    case HD_NOMINAL_MAX_CONTINUOUS_FORCE: out[0] = current_model()->max_continuous_force; break;
    case HD_NOMINAL_MAX_DAMPING: out[0] = current_model()->max_damping; break;
    default: push_error(HD_INVALID_ENUM);
    }
    pthread_mutex_unlock(&lock);
}
void hdGetIntegerv(HDenum param, int *out) {
    pthread_mutex_lock(&lock);
    if (param == HD_CURRENT_BUTTONS) *out = ctl->buttons;
    else if (param == HD_CURRENT_INKWELL_SWITCH) *out = ctl->inkwell;
    else if (param == HD_CALIBRATION_STYLE) *out = ctl->styles;
    else push_error(HD_INVALID_ENUM);
    pthread_mutex_unlock(&lock);
}
const char *hdGetString(HDenum param) {
    if (param == HD_DEVICE_MODEL_TYPE) return current_model()->name;
    if (param == HD_DEVICE_SERIAL_NUMBER) return ctl->serial;
    pthread_mutex_lock(&lock);
    push_error(HD_INVALID_ENUM);
    pthread_mutex_unlock(&lock);
    return NULL;
}
void hdSetDoublev(HDenum param, const double *in) {
    pthread_mutex_lock(&lock);
    if (param == HD_CURRENT_FORCE) {
        double norm = sqrt(in[0] * in[0] + in[1] * in[1] + in[2] * in[2]);
        double scale = 1.0;
        if (!isfinite(norm)) { scale = 0.0; norm = 0.0; }
        double max_force = current_model()->max_force;
        if (norm > max_force + 1e-9) { ctl->forces_clamped++; scale = max_force / norm; } /* HD_MAX_FORCE_CLAMPING */
        for (int i = 0; i < 3; i++) commanded[i] = scale == 0.0 ? 0.0 : in[i] * scale;
    } else {
        push_error(HD_INVALID_ENUM);
    }
    pthread_mutex_unlock(&lock);
}
unsigned int hdCheckCalibration(void) {
    pthread_mutex_lock(&lock);
    unsigned int state = (unsigned int)calibration_state();
    pthread_mutex_unlock(&lock);
    return state;
}
void hdUpdateCalibration(HDenum style) {
    pthread_mutex_lock(&lock);
    ctl->last_update_style = (int32_t)style;
    if (!(style & ctl->styles) || (style & (style - 1))) {
        push_error(HD_INVALID_VALUE); /* not one style, or one the device lacks */
    } else if (style == HD_CALIBRATION_ENCODER_RESET) {
        /* the encoders count from here on: right only if the arm is at the reset pose */
        ctl->resets++;
        if (running) ctl->resets_while_running++;
        const double *hand = ctl->hand;
        ctl->reset_distance_mm = sqrt(hand[0] * hand[0] + hand[1] * hand[1] + hand[2] * hand[2]);
        memcpy(offset, hand, sizeof offset);
        calibrated = 1;
    } else if (style == HD_CALIBRATION_AUTO || (style == HD_CALIBRATION_INKWELL && ctl->inkwell)) {
        memset(offset, 0, sizeof offset); /* the inkwell's or the auto-calibration's known pose */
        calibrated = 1;
    }
    ctl->calibration = calibration_state();
    pthread_mutex_unlock(&lock);
}

/* hdScheduler.h */
HDSchedulerHandle hdScheduleAsynchronous(HDSchedulerCallback cb, void *data, HDushort priority) {
    (void)priority;
    callback = cb;
    callback_data = data;
    return 42;
}
static void *servo(void *arg) {
    (void)arg;
    struct timespec period = {0, 1000000};
    while (running) {
        HDSchedulerCallback cb = ctl->halted ? NULL : callback;
        raised_scheduler_error = 0;
        if (cb && cb(callback_data) == HD_CALLBACK_DONE) {
            callback = NULL;
            ctl->callback_done = 1;
        }
        if (raised_scheduler_error && ctl->stop_calls_on_error) ctl->halted = 1;
        nanosleep(&period, NULL);
    }
    return NULL;
}
void hdStartScheduler(void) {
    if (!running) {
        running = 1;
        ctl->halted = 0;
        ctl->scheduler_running = 1;
        pthread_create(&thread, NULL, servo, NULL);
    }
}
void hdStopScheduler(void) {
    if (running) {
        running = 0;
        pthread_join(thread, NULL);
        ctl->scheduler_running = 0;
    }
}
void hdUnschedule(HDSchedulerHandle h) { (void)h; callback = NULL; }

/* for the test side: the size of struct control, to check its layout */
size_t fake_control_size(void) { return sizeof(struct control); }
