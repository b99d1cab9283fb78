component cia402 "Stand-in for the public cia402 helper component (tests only; written from its published pin list, not its code): drives a CiA402 drive's state machine to operation enabled while enabled and scales positions between mm and counts";
pin in u32 statusword "from the drive (0x6041)";
pin in s32 opmode_display "from the drive (0x6061)";
pin in s32 drv_actual_position "from the drive (0x6064), counts";
pin out u32 controlword "to the drive (0x6040)";
pin out s32 drv_target_position "to the drive (0x607a), counts";
pin in float pos_cmd "position command, mm";
pin out float pos_fb "position feedback, mm";
pin in bit enable "drive enable (joint.N.amp-enable-out)";
pin out bit drv_fault "the drive reports a fault (joint.N.amp-fault-in)";
param rw float pos_scale = 1.0 "counts per mm";
param rw bit csp_mode = 1 "cyclic synchronous position mode (the only one simulated)";
function read_all;
function write_all;
license "GPL";
author "nurbs-motion tests";
include <rtapi_math.h>;
;;
/* Found by the test before it installs a stand-in: a real cia402 is never replaced. */
__attribute__((used)) static const char stand_in[] = "nurbs-motion tests: cia402 stand-in";

FUNCTION(read_all) {
    pos_fb = pos_scale != 0 ? drv_actual_position / pos_scale : 0;
    drv_fault = (statusword & 0x0008) != 0;
}

FUNCTION(write_all) {
    unsigned sw = statusword;
    int operation_enabled = (sw & 0x006f) == 0x0027;
    if (!enable)
        controlword = 0x06;               /* shutdown: ready to switch on, not powered */
    else if (sw & 0x0008)
        controlword = 0x80;               /* fault reset */
    else if ((sw & 0x004f) == 0x0040)
        controlword = 0x06;               /* switch on disabled -> ready to switch on */
    else if ((sw & 0x006f) == 0x0021)
        controlword = 0x07;               /* ready -> switched on */
    else
        controlword = 0x0f;               /* switched on -> operation enabled */
    /* Until operation is enabled the target follows the drive, so enabling does not jump. */
    drv_target_position = enable && operation_enabled && csp_mode
        ? (rtapi_s32)floor(pos_cmd * pos_scale + 0.5) : drv_actual_position;
}
