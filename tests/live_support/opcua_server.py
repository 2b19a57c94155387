"""An OPC UA server (Python asyncua) with Sinumerik-like nodes for the errmap live tests:
in namespace 2 (urn:errmap:test:sinumerik), string node ids
  T.nut, T.bearing, T.room (Double), Coolant (Boolean), X.position (Double), X.direction (Int32),
  SD43900[X], SD43910[X], SD43920[X] (Double, writable by clients).
Security policy None, anonymous. Commands on stdin, one JSON object a line, answered by a line:
  {"op": "set", "node": "T.nut", "value": 21.5}     -> ok
  {"op": "bad", "node": "T.nut"}                    -> ok   (status BadCommunicationError)
  {"op": "get", "node": "SD43910[X]"}               -> the value as JSON
Usage: python opcua_server.py PORT"""
import asyncio
import json
import logging
import sys

from asyncua import Server, ua

logging.disable(logging.WARNING)

TYPES = {
    "T.nut": ua.VariantType.Double,
    "T.bearing": ua.VariantType.Double,
    "T.room": ua.VariantType.Double,
    "Coolant": ua.VariantType.Boolean,
    "X.position": ua.VariantType.Double,
    "X.direction": ua.VariantType.Int32,
    "SD43900[X]": ua.VariantType.Double,
    "SD43910[X]": ua.VariantType.Double,
    "SD43920[X]": ua.VariantType.Double,
}


async def main(port):
    server = Server()
    await server.init()
    server.set_endpoint(f"opc.tcp://127.0.0.1:{port}/")
    server.set_security_policy([ua.SecurityPolicyType.NoSecurity])
    idx = await server.register_namespace("urn:errmap:test:sinumerik")
    folder = await server.nodes.objects.add_folder(ua.NodeId("Machine", idx), "Machine")
    nodes = {}
    for name, vt in TYPES.items():
        initial = False if vt == ua.VariantType.Boolean else (0 if vt == ua.VariantType.Int32 else 0.0)
        node = await folder.add_variable(ua.NodeId(name, idx), name, ua.Variant(initial, vt))
        if name.startswith("SD"):
            await node.set_writable()
        nodes[name] = node
    async with server:
        loop = asyncio.get_running_loop()
        reader = asyncio.StreamReader()
        await loop.connect_read_pipe(lambda: asyncio.StreamReaderProtocol(reader), sys.stdin)
        print("ready", flush=True)
        while True:
            line = await reader.readline()
            if not line:
                break
            cmd = json.loads(line)
            node = nodes[cmd["node"]]
            vt = TYPES[cmd["node"]]
            if cmd["op"] == "set":
                await node.write_value(ua.DataValue(ua.Variant(cmd["value"], vt)))
                print("ok", flush=True)
            elif cmd["op"] == "bad":
                value = await node.read_value()
                await node.write_value(
                    ua.DataValue(
                        ua.Variant(value, vt),
                        StatusCode=ua.StatusCode(ua.StatusCodes.BadCommunicationError),
                    )
                )
                print("ok", flush=True)
            elif cmd["op"] == "get":
                print(json.dumps(await node.read_value()), flush=True)


asyncio.run(main(int(sys.argv[1])))
