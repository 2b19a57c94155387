"""A Modbus TCP server (pymodbus) for the errmap live tests: unit 1 with 64 coils, discrete
inputs, holding and input registers at protocol addresses 0..63. Commands on stdin, one JSON
object a line, each answered with one line on stdout:
  {"op": "set", "fc": 4, "address": 0, "values": [...]}   -> ok
  {"op": "get", "fc": 3, "address": 20, "count": 2}       -> [w0, w1]
fc: 1 coils, 2 discrete inputs, 3 holding registers, 4 input registers.
Usage: python modbus_server.py PORT"""
import asyncio
import json
import logging
import sys

from pymodbus.datastore import (
    ModbusDeviceContext,
    ModbusSequentialDataBlock,
    ModbusServerContext,
)
from pymodbus.server import ModbusTcpServer

logging.disable(logging.WARNING)


async def main(port):
    # pymodbus numbers sequential blocks from 1 (protocol address 0 is block address 1).
    device = ModbusDeviceContext(
        di=ModbusSequentialDataBlock(1, [False] * 64),
        co=ModbusSequentialDataBlock(1, [False] * 64),
        hr=ModbusSequentialDataBlock(1, [0] * 64),
        ir=ModbusSequentialDataBlock(1, [0] * 64),
    )
    context = ModbusServerContext(devices={1: device})
    server = ModbusTcpServer(context, address=("127.0.0.1", port))
    task = asyncio.create_task(server.serve_forever())
    loop = asyncio.get_running_loop()
    reader = asyncio.StreamReader()
    await loop.connect_read_pipe(lambda: asyncio.StreamReaderProtocol(reader), sys.stdin)
    await asyncio.sleep(0.3)
    print("ready", flush=True)
    while True:
        line = await reader.readline()
        if not line:
            break
        cmd = json.loads(line)
        if cmd["op"] == "set":
            # The running server's own store (pymodbus 3.10+ serves a copy of the context).
            err = await server.context.async_setValues(1, cmd["fc"], cmd["address"], cmd["values"])
            print("ok" if err is None else f"error {err}", flush=True)
        elif cmd["op"] == "get":
            values = await server.context.async_getValues(1, cmd["fc"], cmd["address"], cmd["count"])
            print(json.dumps([int(v) for v in values]), flush=True)
    await server.shutdown()
    task.cancel()


asyncio.run(main(int(sys.argv[1])))
