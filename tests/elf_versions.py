"""What an ELF shared object needs from the system, read from its bytes: the machine, the
libraries it names (DT_NEEDED) and the symbol versions it requires from each
(``.gnu.version_r``, the section the dynamic loader checks before it loads the file, and
the one auditwheel reads to place a wheel on a manylinux policy).

Standard library only; little-endian ELF32 and ELF64 (x86, x86-64, aarch64).
"""

from __future__ import annotations

from dataclasses import dataclass
import re
import struct

SHT_DYNAMIC = 6
SHT_GNU_VERNEED = 0x6FFFFFFE
DT_NEEDED = 1
MACHINES = {3: "x86", 62: "x86_64", 183: "aarch64"}


@dataclass
class ElfNeeds:
    machine: str
    needed: list            # DT_NEEDED, in order
    versions: dict          # {library: sorted list of version names it must define}

    def glibc_versions(self):
        """Every GLIBC_x.y required, as (x, y, ...) tuples."""
        out = set()
        for names in self.versions.values():
            for name in names:
                m = re.fullmatch(r"GLIBC_(\d+(?:\.\d+)*)", name)
                if m:
                    out.add(tuple(int(x) for x in m.group(1).split(".")))
        return sorted(out)


def read_elf_needs(data: bytes) -> ElfNeeds:
    """The needs of the ELF file whose bytes are `data`; ValueError if it is not one."""
    if data[:4] != b"\x7fELF":
        raise ValueError("not an ELF file")
    wide = {1: False, 2: True}[data[4]]
    if data[5] != 1:
        raise ValueError("big-endian ELF is not read here")
    if wide:
        (machine,) = struct.unpack_from("<H", data, 18)
        shoff, = struct.unpack_from("<Q", data, 40)
        shentsize, shnum = struct.unpack_from("<HH", data, 58)
    else:
        (machine,) = struct.unpack_from("<H", data, 18)
        shoff, = struct.unpack_from("<I", data, 32)
        shentsize, shnum = struct.unpack_from("<HH", data, 46)
    sections = []
    for i in range(shnum):
        at = shoff + i * shentsize
        if wide:
            _, kind, _, _, offset, size, link, info, _, entsize = struct.unpack_from(
                "<IIQQQQIIQQ", data, at)
        else:
            _, kind, _, _, offset, size, link, info, _, entsize = struct.unpack_from(
                "<IIIIIIIIII", data, at)
        sections.append((kind, offset, size, link, info, entsize))

    def string(section, index):
        _, offset, size, *_ = sections[section]
        end = data.index(b"\0", offset + index)
        return data[offset + index:end].decode()

    needed, versions = [], {}
    for kind, offset, size, link, info, entsize in sections:
        if kind == SHT_DYNAMIC:
            fmt, step = ("<qQ", 16) if wide else ("<iI", 8)
            for at in range(offset, offset + size, step):
                tag, value = struct.unpack_from(fmt, data, at)
                if tag == 0:
                    break
                if tag == DT_NEEDED:
                    needed.append(string(link, value))
        elif kind == SHT_GNU_VERNEED:
            at = offset
            for _ in range(info):                     # sh_info: the number of entries
                _, count, file, aux, nxt = struct.unpack_from("<HHIII", data, at)
                names = versions.setdefault(string(link, file), set())
                a = at + aux
                for _ in range(count):
                    _, _, _, name, anext = struct.unpack_from("<IHHII", data, a)
                    names.add(string(link, name))
                    a += anext
                at += nxt
    return ElfNeeds(MACHINES.get(machine, str(machine)), needed,
                    {lib: sorted(v) for lib, v in versions.items()})
