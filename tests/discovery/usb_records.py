"""USB devices for the umockdev tests, as umockdev record text (``P:`` sysfs path, ``N:`` node, ``E:``
udev properties, ``A:`` sysfs attributes).

Written by hand, not recorded from the devices (none was at hand): the properties are the ones
udev's builtins (``usb_id``, ``v4l_id``) derive from each device's USB descriptors, with the ids the
makers publish (docs/usb.md); the serial numbers are made up in each maker's format. A DIGIT has a
capture node and a metadata node, as every UVC camera on Linux does; the GelSight Mini's serial is
in its product string (its V4L2 name), not in a USB serial descriptor.
"""

from __future__ import annotations

HCD = "/devices/pci0000:00/0000:00:14.0/usb1"


def _usb(port: str, vid: str, pid: str, serial: str, busnum: int, vendor: str, model: str) -> str:
    lines = [f"P: {HCD}/{port}", f"N: bus/usb/001/{busnum:03d}", f"E: DEVNAME=/dev/bus/usb/001/{busnum:03d}",
             "E: DEVTYPE=usb_device", "E: SUBSYSTEM=usb", f"E: ID_VENDOR={vendor}", f"E: ID_VENDOR_ID={vid}",
             f"E: ID_MODEL={model}", f"E: ID_MODEL_ID={pid}", f"A: idVendor={vid}", f"A: idProduct={pid}"]
    if serial:
        lines += [f"E: ID_SERIAL_SHORT={serial}", f"A: serial={serial}"]
    return "\n".join(lines) + "\n"


def _tty(port: str, node: str, minor: int, vid: str, pid: str, serial: str, vendor: str, model: str,
         driver: str = "cdc_acm") -> str:
    kind = "tty" if node.startswith("ttyACM") else f"{node}/tty"
    return "\n".join([
        f"P: {HCD}/{port}/{port}:1.0/{kind}/{node}", f"N: {node}", f"E: DEVNAME=/dev/{node}",
        "E: SUBSYSTEM=tty",
        f"E: MAJOR={166 if node.startswith('ttyACM') else 188}", f"E: MINOR={minor}", "E: ID_BUS=usb",
        f"E: ID_VENDOR={vendor}", f"E: ID_VENDOR_ID={vid}", f"E: ID_MODEL={model}", f"E: ID_MODEL_ID={pid}",
        f"E: ID_SERIAL={vendor}_{model}_{serial}", f"E: ID_SERIAL_SHORT={serial}",
        "E: ID_USB_INTERFACE_NUM=00",
        f"E: ID_USB_DRIVER={driver}", f"A: dev={166 if node.startswith('ttyACM') else 188}:{minor}",
    ]) + "\n"


def _video(port: str, index: int, vid: str, pid: str, serial: str, vendor: str, model: str, card: str,
           capture: bool) -> str:
    lines = [f"P: {HCD}/{port}/{port}:1.0/video4linux/video{index}", f"N: video{index}",
             f"E: DEVNAME=/dev/video{index}", "E: SUBSYSTEM=video4linux", "E: MAJOR=81", f"E: MINOR={index}",
             "E: ID_V4L_VERSION=2", f"E: ID_V4L_PRODUCT={card}",
             f"E: ID_V4L_CAPABILITIES={':capture:' if capture else ':'}", "E: ID_BUS=usb",
             f"E: ID_VENDOR={vendor}", f"E: ID_VENDOR_ID={vid}", f"E: ID_MODEL={model}",
             f"E: ID_MODEL_ID={pid}", "E: ID_USB_DRIVER=uvcvideo", "E: ID_TYPE=video", f"A: dev=81:{index}",
             f"A: name={card}"]
    if serial:
        lines += [f"E: ID_SERIAL={vendor}_{model}_{serial}", f"E: ID_SERIAL_SHORT={serial}"]
    return "\n".join(lines) + "\n"


def join(*parts: str) -> str:
    return "\n".join(parts)


DIGIT_SERIAL = "D20001"
DIGIT = join(_usb("1-1", "2833", "0209", DIGIT_SERIAL, 2, "Facebook", "DIGIT"),
             _video("1-1", 0, "2833", "0209", DIGIT_SERIAL, "Facebook", "DIGIT", "DIGIT: DIGIT", True),
             _video("1-1", 1, "2833", "0209", DIGIT_SERIAL, "Facebook", "DIGIT", "DIGIT: DIGIT", False))

MINI_SERIAL = "2BG8-0H3X"
SONIX = "Sonix_Technology_Co.__Ltd."
MINI = join(_usb("1-4", "0c45", "636d", "", 3, SONIX, f"GelSight_Mini_R0B_{MINI_SERIAL}"),
            _video("1-4", 2, "0c45", "636d", "", SONIX, f"GelSight_Mini_R0B_{MINI_SERIAL}",
                   f"GelSight Mini R0B {MINI_SERIAL}: Ge", True))

QTPY_SERIAL = "9F1E2A0C50533"
QTPY = join(_usb("1-2", "239a", "80cb", QTPY_SERIAL, 5, "Adafruit", "QT_Py_M0"),
            _tty("1-2", "ttyACM0", 0, "239a", "80cb", QTPY_SERIAL, "Adafruit", "QT_Py_M0"))
QTPY_REPLUGGED = join(_usb("1-3", "239a", "80cb", QTPY_SERIAL, 7, "Adafruit", "QT_Py_M0"),
                      _tty("1-3", "ttyACM1", 1, "239a", "80cb", QTPY_SERIAL, "Adafruit", "QT_Py_M0"))
"""The same board plugged in again, into another port: another node (umockdev keeps the first)."""

UNO_SERIAL = "85734323430351D0E1C1"
UNO = join(_usb("1-5", "2341", "0043", UNO_SERIAL, 4, "Arduino__www.arduino.cc_", "0043"),
           _tty("1-5", "ttyACM2", 2, "2341", "0043", UNO_SERIAL, "Arduino__www.arduino.cc_", "0043"))

FTDI_SERIAL = "FT6S4DSP"
FTDI = join(_usb("1-6", "0403", "6001", FTDI_SERIAL, 6, "FTDI", "FT232R_USB_UART"),
            _tty("1-6", "ttyUSB0", 0, "0403", "6001", FTDI_SERIAL, "FTDI", "FT232R_USB_UART", "ftdi_sio"))
