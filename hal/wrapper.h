/* Input to `make bindings` (bindgen): the HAL/RTAPI API our module and planner call.
 * Generated with -DRTAPI -DUSPACE; every function we bind has the same prototype under ULAPI. */
#include <rtapi.h>
#include <hal.h>
