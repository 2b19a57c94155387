# errmap live's HAL helper: a LinuxCNC userspace HAL component that errmap starts as a child
# process (`python3 -c <this file> <spec>`) and talks to over its standard input and output.
# It uses LinuxCNC's own Python `hal` module, so errmap itself needs no LinuxCNC library.
#
# The spec (JSON, argv[1]): {"component": NAME, "pins": [{"name", "type", "net", "signal"}]}.
# Every pin is an output of the component; a pin with "net" is linked to that HAL pin (for
# example axis.z.eoffset-counts) through the signal the pin is already on, or through a new
# signal named "signal". Before a link the new pin takes the value the other pin reads now, so
# linking changes nothing LinuxCNC sees.
#
# Requests, one line each, answered with one line carrying the same number:
#   N get NAME...          ->  N ok VALUE...   (b1/b0 a bit, i<n> an integer, f<x> a float)
#   N set PIN=VALUE...     ->  N ok            (the component's own pins)
#   any failure            ->  N err MESSAGE
# At the end of standard input the component exits; its signals keep their last values.
import json
import subprocess
import sys

import hal

TYPES = {"bit": hal.HAL_BIT, "float": hal.HAL_FLOAT, "s32": hal.HAL_S32, "u32": hal.HAL_U32}


def linked_signal(pin):
    """The signal `pin` is linked to (None when it is not), from `halcmd show pin`."""
    out = subprocess.run(
        ["halcmd", "-s", "show", "pin", pin], capture_output=True, text=True, timeout=20
    ).stdout
    for line in out.splitlines():
        fields = line.split()
        if pin in fields:
            i = fields.index(pin)
            if len(fields) > i + 2 and fields[i + 1] in ("<==", "==>", "<=>"):
                return fields[i + 2]
            return None
    raise RuntimeError("there is no HAL pin %s (is LinuxCNC running, with this axis?)" % pin)


def driver_of(signal):
    """(exists, the pin driving `signal` or None)."""
    for s in hal.get_info_signals():
        if s["NAME"] == signal:
            return True, s.get("DRIVER")
    return False, None


def link(comp, prefix, pin, kind, other, new_signal):
    signal = linked_signal(other)
    if signal is None:
        signal = new_signal
    exists, driver = driver_of(signal)
    if driver:
        raise RuntimeError(
            "%s is already driven by %s (signal %s): remove that net for errmap to drive it"
            % (other, driver, signal)
        )
    comp[pin] = hal.get_value(other)
    if not exists:
        hal.new_sig(signal, TYPES[kind])
    hal.connect(prefix + pin, signal)
    if linked_signal(other) is None:
        hal.connect(other, signal)


def text(value):
    if isinstance(value, bool):
        return "b1" if value else "b0"
    if isinstance(value, int):
        return "i%d" % value
    return "f%r" % float(value)


def typed(kind, value):
    if kind == "bit":
        return bool(int(value))
    if kind in ("s32", "u32"):
        return int(value)
    return float(value)


def main():
    spec = json.loads(sys.argv[1])
    prefix = spec["component"] + "."
    kinds = {}
    try:
        comp = hal.component(spec["component"])
        for p in spec["pins"]:
            comp.newpin(p["name"], TYPES[p["type"]], hal.HAL_OUT)
            kinds[p["name"]] = p["type"]
        comp.ready()
        for p in spec["pins"]:
            if p.get("net"):
                link(comp, prefix, p["name"], p["type"], p["net"], p["signal"])
    except Exception as e:  # the message goes to errmap, which stops with it
        print("0 err %s" % " ".join(str(e).split()), flush=True)
        return 1
    print("0 ready", flush=True)
    for line in sys.stdin:
        fields = line.split()
        if len(fields) < 2:
            continue
        number, verb, args = fields[0], fields[1], fields[2:]
        try:
            if verb == "get":
                reply = "ok " + " ".join(text(hal.get_value(n)) for n in args)
            elif verb == "set":
                for a in args:
                    name, value = a.split("=", 1)
                    comp[name] = typed(kinds[name], value)
                reply = "ok"
            else:
                reply = "err unknown request " + verb
        except Exception as e:
            reply = "err %s" % " ".join(str(e).split())
        print("%s %s" % (number, reply), flush=True)
    return 0


sys.exit(main())
