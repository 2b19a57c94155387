# A headless LinuxCNC "display" for tests/live_linuxcnc.rs: LinuxCNC starts it as [DISPLAY]
# DISPLAY with -ini FILE. Through LinuxCNC's Python module it resets the E-stop, turns the
# machine on, homes every joint and appends "ready" to display.log beside the INI file; then it
# takes one command a line from its standard input (the test's pipe into `linuxcnc`):
#   mdi <G-code>   run it in MDI mode and wait until done
#   off / on       machine off / on
# appending "done <line>" (or "failed <line>: why") for each. At the end of its input it exits,
# and LinuxCNC shuts down.
import os
import sys
import time

import linuxcnc

here = os.path.dirname(os.path.abspath(sys.argv[sys.argv.index("-ini") + 1]))
log = open(os.path.join(here, "display.log"), "a", buffering=1)
s = linuxcnc.stat()
c = linuxcnc.command()


def wait(what, ok, seconds=20):
    until = time.time() + seconds
    while time.time() < until:
        s.poll()
        if ok():
            return
        time.sleep(0.02)
    raise RuntimeError("timed out waiting for " + what)


for _ in range(400):
    try:
        s.poll()
        break
    except linuxcnc.error:
        time.sleep(0.05)
c.state(linuxcnc.STATE_ESTOP_RESET)
c.wait_complete()
c.state(linuxcnc.STATE_ON)
c.wait_complete()
c.home(-1)
c.wait_complete()
wait("homing", lambda: all(s.homed[j] for j in range(s.joints)))
log.write("ready\n")

for line in sys.stdin:
    line = line.strip()
    if not line:
        continue
    try:
        if line.startswith("mdi "):
            c.mode(linuxcnc.MODE_MDI)
            c.wait_complete()
            c.mdi(line[4:])
            c.wait_complete(30)
            wait("the move", lambda: s.interp_state == linuxcnc.INTERP_IDLE and s.inpos)
        elif line == "off":
            c.state(linuxcnc.STATE_OFF)
            c.wait_complete()
            wait("machine off", lambda: not s.enabled)
        elif line == "on":
            c.state(linuxcnc.STATE_ON)
            c.wait_complete()
            wait("machine on", lambda: s.enabled)
        else:
            raise RuntimeError("unknown command")
        log.write("done %s\n" % line)
    except Exception as e:
        log.write("failed %s: %s\n" % (line, e))
