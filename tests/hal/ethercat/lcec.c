/* Stand-in for the LinuxCNC EtherCAT driver `lcec` (test use only; written from the public
 * description of its pins and functions, not from its code). It exports `lcec.read-all` and
 * `lcec.write-all` and, for every PDO entry of the XML that the stand-in `lcec_conf` published,
 * the pin `lcec.<master>.<slave>.<halPin>`. Each slave is a simulated CiA402 drive in cyclic
 * synchronous position mode: its state machine answers the controlword (0x6040) in the
 * statusword (0x6041), the mode display (0x6061) reads 8 (CSP), and once operation is enabled
 * its actual position (0x6064) is the target position (0x607a) of the previous cycle. No bus,
 * no distributed clocks, no timing: what it proves is names, types, directions and the order
 * of the functions in the servo thread. */
#include "rtapi.h"
#include "rtapi_app.h"
#include "rtapi_string.h"
#include "hal.h"
#include <stdio.h>
#include <string.h>

MODULE_LICENSE("GPL");
MODULE_AUTHOR("nurbs-motion tests");
MODULE_DESCRIPTION("Stand-in for lcec: simulated CiA402 drives (tests only)");

/* Found by the test before it installs a stand-in: a real lcec is never replaced. */
__attribute__((used)) static const char stand_in[] = "nurbs-motion tests: lcec stand-in";

#define CONF_KEY 0x4c434543
#define CONF_SIZE 8192
#define MAX_SLAVES 16

/* Statusword values of the states the simulated drive passes. */
#define SW_SWITCH_ON_DISABLED 0x0040
#define SW_READY_TO_SWITCH_ON 0x0021
#define SW_SWITCHED_ON 0x0023
#define SW_OPERATION_ENABLED 0x0027

typedef struct {
    hal_u32_t *controlword; /* 0x6040, from the master */
    hal_s32_t *target;      /* 0x607a, from the master */
    hal_u32_t *statusword;  /* 0x6041, to the master */
    hal_s32_t *actual;      /* 0x6064, to the master */
    hal_s32_t *opmode;      /* 0x6061, to the master */
} slave_pins_t;

typedef struct {
    char name[48];
    slave_pins_t *pins;
    hal_u32_t state;
    hal_s32_t position;
} slave_t;

static int comp_id = -1;
static int conf_id = -1;
static slave_t slaves[MAX_SLAVES];
static int n_slaves;

static slave_t *slave_named(const char *name)
{
    int i;
    for (i = 0; i < n_slaves; i++)
        if (strcmp(slaves[i].name, name) == 0)
            return &slaves[i];
    if (n_slaves == MAX_SLAVES || strlen(name) >= sizeof(slaves[0].name))
        return NULL;
    rtapi_strlcpy(slaves[n_slaves].name, name, sizeof(slaves[0].name));
    slaves[n_slaves].pins = hal_malloc(sizeof(slave_pins_t));
    if (!slaves[n_slaves].pins)
        return NULL;
    memset(slaves[n_slaves].pins, 0, sizeof(slave_pins_t));
    slaves[n_slaves].state = SW_SWITCH_ON_DISABLED;
    return &slaves[n_slaves++];
}

/* One line of the published configuration: makes the pin. */
static int make_pin(const char *line)
{
    char master[16], slave[48], pin[48], type[8], dir[8];
    unsigned idx;
    slave_t *s;
    slave_pins_t *p;
    if (sscanf(line, "%15s %47s %47s %7s %7s %x", master, slave, pin, type, dir, &idx) != 6)
        return -1;
    s = slave_named(slave);
    if (!s)
        return -1;
    p = s->pins;
    switch (idx) {
    case 0x6040: return hal_pin_u32_newf(HAL_IN, &p->controlword, comp_id, "lcec.%s.%s.%s", master, slave, pin);
    case 0x607a: return hal_pin_s32_newf(HAL_IN, &p->target, comp_id, "lcec.%s.%s.%s", master, slave, pin);
    case 0x6041: return hal_pin_u32_newf(HAL_OUT, &p->statusword, comp_id, "lcec.%s.%s.%s", master, slave, pin);
    case 0x6064: return hal_pin_s32_newf(HAL_OUT, &p->actual, comp_id, "lcec.%s.%s.%s", master, slave, pin);
    case 0x6061: return hal_pin_s32_newf(HAL_OUT, &p->opmode, comp_id, "lcec.%s.%s.%s", master, slave, pin);
    default:
        rtapi_print_msg(RTAPI_MSG_ERR, "lcec stand-in: object %04x (%s.%s) is not simulated\n", idx, slave, pin);
        return -1;
    }
}

static void read_all(void *arg, long period)
{
    int i;
    for (i = 0; i < n_slaves; i++) {
        slave_pins_t *p = slaves[i].pins;
        if (p->statusword) *p->statusword = slaves[i].state;
        if (p->actual) *p->actual = slaves[i].position;
        if (p->opmode) *p->opmode = 8;
    }
}

/* The CiA402 state machine, one transition per cycle as a drive makes them. */
static hal_u32_t next_state(hal_u32_t state, hal_u32_t cw)
{
    int shutdown = (cw & 0x87) == 0x06, switch_on = (cw & 0x8f) == 0x07, enable = (cw & 0x8f) == 0x0f;
    if (!(cw & 0x02))
        return SW_SWITCH_ON_DISABLED; /* disable voltage */
    switch (state) {
    case SW_SWITCH_ON_DISABLED: return shutdown ? SW_READY_TO_SWITCH_ON : state;
    case SW_READY_TO_SWITCH_ON: return switch_on || enable ? SW_SWITCHED_ON : state;
    case SW_SWITCHED_ON: return enable ? SW_OPERATION_ENABLED : shutdown ? SW_READY_TO_SWITCH_ON : state;
    default: return enable ? state : switch_on ? SW_SWITCHED_ON : SW_READY_TO_SWITCH_ON;
    }
}

static void write_all(void *arg, long period)
{
    int i;
    for (i = 0; i < n_slaves; i++) {
        slave_pins_t *p = slaves[i].pins;
        hal_u32_t cw = p->controlword ? *p->controlword : 0;
        slaves[i].state = next_state(slaves[i].state, cw);
        /* CSP: at the target by the next cycle's read. */
        if (slaves[i].state == SW_OPERATION_ENABLED && p->target)
            slaves[i].position = *p->target;
    }
}

int rtapi_app_main(void)
{
    void *conf;
    char *text, *line, *end;
    comp_id = hal_init("lcec");
    if (comp_id < 0)
        return comp_id;
    conf_id = rtapi_shmem_new(CONF_KEY, comp_id, CONF_SIZE);
    if (conf_id < 0 || rtapi_shmem_getptr(conf_id, &conf) < 0) {
        rtapi_print_msg(RTAPI_MSG_ERR, "lcec stand-in: no configuration (run the stand-in lcec_conf first)\n");
        hal_exit(comp_id);
        return -1;
    }
    text = (char *)conf;
    text[CONF_SIZE - 1] = 0;
    if (!text[0]) {
        rtapi_print_msg(RTAPI_MSG_ERR, "lcec stand-in: the configuration is empty\n");
        hal_exit(comp_id);
        return -1;
    }
    for (line = text; *line; line = end + 1) {
        end = strchr(line, '\n');
        if (!end)
            break;
        *end = 0;
        if (make_pin(line) < 0) {
            rtapi_print_msg(RTAPI_MSG_ERR, "lcec stand-in: cannot make the pin of '%s'\n", line);
            hal_exit(comp_id);
            return -1;
        }
        *end = '\n';
    }
    if (hal_export_funct("lcec.read-all", read_all, 0, 0, 0, comp_id) < 0 ||
        hal_export_funct("lcec.write-all", write_all, 0, 0, 0, comp_id) < 0) {
        hal_exit(comp_id);
        return -1;
    }
    hal_ready(comp_id);
    return 0;
}

void rtapi_app_exit(void)
{
    if (conf_id >= 0)
        rtapi_shmem_delete(conf_id, comp_id);
    hal_exit(comp_id);
}
