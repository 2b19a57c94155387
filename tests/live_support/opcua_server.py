"""An OPC UA server (Python asyncua) with Sinumerik-like nodes for the errmap live tests:
in namespace 2 (urn:errmap:test:sinumerik), string node ids
  T.nut, T.bearing, T.room (Double), Coolant (Boolean), X.position (Double), X.direction (Int32),
  SD43900[X], SD43910[X], SD43920[X], Comp[X] (Double, writable by clients).
Security policy None; anonymous, or with USER and PASSWORD only that user name and password
(asyncua's user manager; anything else is refused with BadUserAccessDenied, anonymous with
BadIdentityTokenRejected). Commands on stdin, one JSON object a line, answered by a line:
  {"op": "set", "node": "T.nut", "value": 21.5}     -> ok
  {"op": "bad", "node": "T.nut"}                    -> ok   (status BadCommunicationError)
  {"op": "get", "node": "SD43910[X]"}               -> the value as JSON
  {"op": "logins"}                                  -> {"accepted": N, "refused": M}
Usage: python opcua_server.py PORT [USER PASSWORD]"""
import asyncio
import json
import logging
import sys

from asyncua import Server, ua
from asyncua.crypto.permission_rules import User, UserRole

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
    "Comp[X]": ua.VariantType.Double,
}


class OneUser:
    """asyncua's user manager interface: the one user name and password, nobody else."""

    def __init__(self, user, password):
        self.user, self.password = user, password
        self.accepted, self.refused = 0, 0

    def get_user(self, iserver, username=None, password=None, certificate=None):
        if username == self.user and password == self.password:
            self.accepted += 1
            return User(role=UserRole.User, name=username)
        self.refused += 1
        return None


async def main(port, login):
    users = OneUser(*login) if login else None
    server = Server(user_manager=users)
    await server.init()
    server.set_endpoint(f"opc.tcp://127.0.0.1:{port}/")
    server.set_security_policy([ua.SecurityPolicyType.NoSecurity])
    if users:
        server.set_identity_tokens([ua.UserNameIdentityToken])
    idx = await server.register_namespace("urn:errmap:test:sinumerik")
    folder = await server.nodes.objects.add_folder(ua.NodeId("Machine", idx), "Machine")
    nodes = {}
    for name, vt in TYPES.items():
        initial = False if vt == ua.VariantType.Boolean else (0 if vt == ua.VariantType.Int32 else 0.0)
        node = await folder.add_variable(ua.NodeId(name, idx), name, ua.Variant(initial, vt))
        if name.startswith("SD") or name.startswith("Comp"):
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
            if cmd["op"] == "logins":
                counts = {"accepted": users.accepted, "refused": users.refused} if users else {}
                print(json.dumps(counts), flush=True)
                continue
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


asyncio.run(main(int(sys.argv[1]), sys.argv[2:4]))
