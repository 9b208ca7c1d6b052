// Definitions the course library's components/hbridge_interface.h declares but never defines:
// HBridgeInterface::standby_on() and standby_off(). The first is the class's key function, so
// without a definition no translation unit emits HBridgeInterface's virtual table and the link
// fails with "undefined reference to vtable for HBridgeInterface". Compiled into the
// firmware-in-the-loop build only (tests/test_firmware_fil.py); the TB6612FNG driver overrides
// both, so these empty bodies never run on the cart. Written for cartctl.
#include "hbridge_interface.h"

void HBridgeInterface::standby_on() {}
void HBridgeInterface::standby_off() {}
