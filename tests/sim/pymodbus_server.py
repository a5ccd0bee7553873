#!/usr/bin/python3
"""An independent Modbus TCP peer for interoperability checks: pymodbus (Debian's
python3-pymodbus 3.0) serving the int16 pose-registers block of proto/modbus.md.

It listens on 127.0.0.1 on a free port, writes that port and a newline to --port-file once it
listens (temp file + rename), appends one line per write it applies to --log in the format of
fieldgrip-sim:

    write unit=U fn=F addr=A n=N words=W1,W2,...

(decimal, A the protocol address) and acknowledges a new seq like the robot program of
proto/modbus.md: status = 1 and ack = seq, then status = 2 after --done-delay-ms.

Differences from fieldgrip-sim, all from pymodbus: requests for other unit ids get no reply
at all (its framer drops them), and writes outside the block are answered with exception 2
but not logged (pymodbus validates the range before the data store sees the write).

SIGTERM or SIGINT stops it with exit status 0.
"""
import argparse
import asyncio
import logging
import os
import signal
import sys

from pymodbus.datastore import (ModbusSequentialDataBlock, ModbusServerContext,
                                ModbusSlaveContext)
from pymodbus.server import StartAsyncTcpServer

BLOCK_REGS = 16  # int16 layout: offsets 0..15 (the block, ack, status, stop)
ACK, STATUS = 13, 14
WRITE_FUNCTIONS = (6, 16, 22, 23)


class RobotContext(ModbusSlaveContext):
    """One unit's registers: the robot block at base, with each write logged and seq
    acknowledged.

    zero_mode=True matters: without it ModbusSlaveContext adds 1 to every protocol address
    before it reaches the data block (pymodbus' 1-based register numbering), so the block
    created at `base` would be one off."""

    def __init__(self, unit, base, log, ack_delay_s, done_delay_s):
        block = ModbusSequentialDataBlock(base, [0] * BLOCK_REGS)
        super().__init__(hr=block, zero_mode=True)
        self.unit = unit
        self.base = base
        self.log = log
        self.ack_delay_s = ack_delay_s
        self.done_delay_s = done_delay_s
        self.pending = None  # asyncio handle of the scheduled ack or done

    def _reg(self, offset):
        return super().getValues(3, self.base + offset, 1)[0]

    def _set(self, offset, values):
        super().setValues(16, self.base + offset, values)

    def setValues(self, fc_as_hex, address, values):  # pylint: disable=invalid-name
        if fc_as_hex in WRITE_FUNCTIONS:
            words = ",".join(str(v) for v in values)
            self.log.write(f"write unit={self.unit} fn={fc_as_hex} addr={address} "
                           f"n={len(values)} words={words}\n")
            self.log.flush()
        super().setValues(fc_as_hex, address, values)
        if fc_as_hex in WRITE_FUNCTIONS and address <= self.base < address + len(values):
            self._on_seq_write()

    def _on_seq_write(self):
        seq = self._reg(0)
        if seq == 0 or seq == self._reg(ACK):
            return
        if self.pending is not None:  # a newer seq supersedes the unfinished one
            self.pending.cancel()
            self.pending = None
        loop = asyncio.get_running_loop()
        if self.ack_delay_s > 0:
            self.pending = loop.call_later(self.ack_delay_s, self._ack, seq)
        else:
            self._ack(seq)

    def _ack(self, seq):
        self._set(ACK, [seq, 1])  # ack and status = 1 (busy) together
        self.pending = asyncio.get_running_loop().call_later(self.done_delay_s, self._done)

    def _done(self):
        self.pending = None
        self._set(STATUS, [2])


def write_port_file(path, port):
    tmp = f"{path}.tmp.{os.getpid()}"
    with open(tmp, "w", encoding="ascii") as f:
        f.write(f"{port}\n")
        f.flush()
        os.fsync(f.fileno())
    os.rename(tmp, path)


async def serve(args, log):
    context = ModbusServerContext(
        slaves={args.unit: RobotContext(args.unit, args.base, log, args.ack_delay_ms / 1000.0,
                                        args.done_delay_ms / 1000.0)},
        single=False)
    server = await StartAsyncTcpServer(context, address=("127.0.0.1", 0), defer_start=True,
                                       allow_reuse_address=True)
    task = asyncio.create_task(server.serve_forever())
    await server.serving
    port = server.server.sockets[0].getsockname()[1]
    write_port_file(args.port_file, port)
    print(f"pymodbus_server: listening on 127.0.0.1:{port}", file=sys.stderr, flush=True)

    stop = asyncio.Event()
    loop = asyncio.get_running_loop()
    for sig in (signal.SIGTERM, signal.SIGINT):
        loop.add_signal_handler(sig, stop.set)
    await stop.wait()
    await server.shutdown()
    task.cancel()
    try:
        await task
    except asyncio.CancelledError:
        pass


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n", 1)[0])
    parser.add_argument("--port-file", required=True)
    parser.add_argument("--log", required=True)
    parser.add_argument("--base", type=int, default=128)
    parser.add_argument("--unit", type=int, default=1)
    parser.add_argument("--ack-delay-ms", type=int, default=0)
    parser.add_argument("--done-delay-ms", type=int, default=0)
    args = parser.parse_args()
    if not 0 <= args.base <= 65536 - BLOCK_REGS:
        parser.error(f"--base must be in 0..{65536 - BLOCK_REGS}")
    if not 0 <= args.unit <= 247:
        parser.error("--unit must be in 0..247")
    # pymodbus logs every client disconnect as an error; keep stderr for real trouble.
    logging.getLogger("pymodbus").setLevel(logging.CRITICAL)
    with open(args.log, "a", encoding="ascii") as log:
        asyncio.run(serve(args, log))


if __name__ == "__main__":
    main()
