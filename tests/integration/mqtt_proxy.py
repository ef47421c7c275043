"""A TCP relay between vmacd and a real Mosquitto that reads every MQTT
CONNECT packet going through it, as the Sparkplug TCK's monitor reads them:
the client id and the will (topic and payload), so a test can see each
CONNECT's NDEATH will and its bdSeq, including those the broker refused.
It can also cut the connections of one client id and keep closing its new
ones (a main connection lost while the Sparkplug one stays), and it keeps
when each connection began (its CONNECT) and ended (the client's side
closed), so a test can see whether a client held two at once. Everything
else is passed through untouched in both directions."""

import socket
import threading
import time


def _varint_len(data, i):
    """MQTT's remaining length at data[i:]: (value, index after it)."""
    mult, value = 1, 0
    while True:
        if i >= len(data):
            raise ValueError("truncated remaining length")
        b = data[i]
        i += 1
        value += (b & 0x7F) * mult
        if not b & 0x80:
            return value, i
        mult *= 128
        if mult > 128 ** 3:
            raise ValueError("remaining length too long")


def _string(data, i):
    n = int.from_bytes(data[i:i + 2], "big")
    return data[i + 2:i + 2 + n], i + 2 + n


def connect_flags(packet):
    """A CONNECT's flags (MQTT 3.1.1, 3.1.2.3): clean session, will QoS and
    will retain."""
    _, i = _varint_len(packet, 1)
    _, i = _string(packet, i)
    flags = packet[i + 1]
    return {"clean": bool(flags & 0x02), "will_qos": (flags >> 3) & 3, "will_retain": bool(flags & 0x20)}


def parse_connect(packet):
    """(client id, will topic or None, will payload or None) of a CONNECT
    (MQTT 3.1.1, section 3.1)."""
    if not packet or packet[0] >> 4 != 1:
        raise ValueError("not a CONNECT")
    _, i = _varint_len(packet, 1)
    _, i = _string(packet, i)  # protocol name
    i += 1  # level
    flags = packet[i]
    i += 3  # flags, keep alive
    client_id, i = _string(packet, i)
    will_topic = will_payload = None
    if flags & 0x04:
        will_topic, i = _string(packet, i)
        will_payload, i = _string(packet, i)
    return client_id.decode(), will_topic.decode() if will_topic is not None else None, will_payload


class MqttProxy:
    """Listens on 127.0.0.1:port (a free one) and relays to the broker's
    port. connects: (client id, will topic, will payload) of every CONNECT
    seen, in order; cond is notified on each."""

    def __init__(self, broker_port):
        self.broker_port = broker_port
        self.cond = threading.Condition()
        self.connects = []
        self.flags = []  # connect_flags() of each CONNECT, as connects
        self.publishes = []  # (client id, topic, QoS, retain, connection) of every PUBLISH a client sent
        self.spans = []  # [monotonic time of the CONNECT, of the client's close or None], as connects
        self.blocked = set()
        self.live = []  # (client id, client socket, broker socket)
        self.port = 0
        self.closed = False
        self._listen()

    def _listen(self):
        self.srv = socket.socket()
        self.srv.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        self.srv.bind(("127.0.0.1", self.port))
        self.srv.listen(16)
        self.port = self.srv.getsockname()[1]
        threading.Thread(target=self._accept, args=(self.srv,), daemon=True).start()

    @property
    def url(self):
        return "mqtt://127.0.0.1:%d" % self.port

    def _accept(self, srv):
        while not self.closed:
            try:
                client, _ = srv.accept()
            except OSError:
                return
            threading.Thread(target=self._session, args=(client,), daemon=True).start()

    @staticmethod
    def _read_packet(sock):
        """One whole MQTT packet (the CONNECT comes first), or None."""
        data = b""
        while True:
            try:
                length, i = _varint_len(data, 1)
                if len(data) >= i + length:
                    return data
            except ValueError:
                if len(data) > 5:
                    return None
            chunk = sock.recv(65536)
            if not chunk:
                return None
            data += chunk

    def _session(self, client):
        packet = self._read_packet(client)
        try:
            cid, will_topic, will_payload = parse_connect(packet)
        except (ValueError, IndexError, UnicodeDecodeError):
            client.close()
            return
        with self.cond:
            self.connects.append((cid, will_topic, will_payload))
            self.flags.append(connect_flags(packet))
            self.spans.append([time.monotonic(), None])
            conn = len(self.connects) - 1  # this connection: the index of its CONNECT
            self.cond.notify_all()
            blocked = cid in self.blocked
        if blocked:
            client.close()
            self._ended(conn)
            return
        upstream = socket.create_connection(("127.0.0.1", self.broker_port))
        upstream.sendall(packet)
        with self.cond:
            self.live.append((cid, client, upstream))
        threading.Thread(target=self._pipe, args=(client, upstream, cid, conn), daemon=True).start()
        threading.Thread(target=self._pipe, args=(upstream, client), daemon=True).start()

    def _pipe(self, src, dst, cid=None, conn=None):
        """src to dst as it comes; from a client (cid), its PUBLISH packets
        are read on the way (3.3.1: QoS and retain in the fixed header)."""
        pending = b""
        try:
            while True:
                data = src.recv(65536)
                if not data:
                    break
                dst.sendall(data)
                if cid is None:
                    continue
                pending += data
                while pending:
                    try:
                        length, i = _varint_len(pending, 1)
                    except ValueError:
                        break
                    if len(pending) < i + length:
                        break
                    packet, pending = pending[:i + length], pending[i + length:]
                    if packet[0] >> 4 == 3:
                        topic, _ = _string(packet, i)
                        with self.cond:
                            self.publishes.append((cid, topic.decode("utf-8", "replace"), (packet[0] >> 1) & 3,
                                                   bool(packet[0] & 1), conn))
        except OSError:
            pass
        if cid is not None:
            self._ended(conn)
        for s in (src, dst):
            try:
                s.shutdown(socket.SHUT_RDWR)
            except OSError:
                pass

    def _ended(self, conn):
        with self.cond:
            if self.spans[conn][1] is None:
                self.spans[conn][1] = time.monotonic()
            self.cond.notify_all()

    def overlaps(self, suffix):
        """Pairs of connections of client ids ending in suffix that were
        open at the same time: (client id, CONNECT index) of each."""
        with self.cond:
            mine = [(self.spans[i][0], self.spans[i][1], (c[0], i)) for i, c in enumerate(self.connects)
                    if c[0].endswith(suffix)]
        mine.sort(key=lambda x: x[0])
        return [(a[2], b[2]) for a, b in zip(mine, mine[1:]) if a[1] is None or a[1] > b[0]]

    def wait_connects(self, predicate, timeout_s, what):
        """Until predicate(connects) holds; the list."""
        with self.cond:
            if not self.cond.wait_for(lambda: predicate(self.connects), timeout_s):
                raise AssertionError("%s: not within %.0f s; CONNECTs seen: %s" % (
                    what, timeout_s, [(c, t) for c, t, _ in self.connects]))
            return list(self.connects)

    def _cut(self, which):
        with self.cond:
            cut = [(c, u) for cid, c, u in self.live if which(cid)]
        for pair in cut:
            for s in pair:
                try:
                    s.shutdown(socket.SHUT_RDWR)
                except OSError:
                    pass

    def block(self, client_id):
        """Cut client_id's connections (no DISCONNECT: the broker sees the
        socket close) and close its new ones at once."""
        with self.cond:
            self.blocked.add(client_id)
        self._cut(lambda cid: cid == client_id)

    def pause(self):
        """The server gone: every connection cut and no listener, so a
        client's TCP connect is refused (no CONNECT packet is sent)."""
        try:  # wakes the accepting thread and stops listening at once (close alone waits for it)
            self.srv.shutdown(socket.SHUT_RDWR)
        except OSError:
            pass
        self.srv.close()
        self._cut(lambda cid: True)

    def resume(self):
        """Listening again on the same port."""
        self._listen()

    def unblock(self, client_id):
        with self.cond:
            self.blocked.discard(client_id)

    def close(self):
        self.closed = True
        try:
            self.srv.close()
        except OSError:
            pass


def client_ids(connects, suffix):
    return [c for c in connects if c[0].endswith(suffix)]

