"""FINS end codes (manual 5-1-3): the whole table as data, and the flag bits.

The end code travels as two bytes, MRES and SRES::

    MRES: bit 7 relay error | bits 6-0 main code
    SRES: bit 7 fatal CPU error | bit 6 non-fatal CPU error | bits 5-0 sub code

``0x0040`` and ``0x0080`` are *normal completions* that carry a CPU error flag: the command
worked, and the PLC currently has a (non-)fatal error.
"""

from __future__ import annotations

from dataclasses import dataclass

RELAY_ERROR_FLAG = 0x8000
FATAL_CPU_ERROR_FLAG = 0x0080
NON_FATAL_CPU_ERROR_FLAG = 0x0040
#: Both CPU error flags (bits 6 and 7): they ride on any end code, normal or not.
CPU_ERROR_FLAGS = FATAL_CPU_ERROR_FLAG | NON_FATAL_CPU_ERROR_FLAG
END_CODE_MASK = 0x7F3F


@dataclass(frozen=True, slots=True)
class EndCodeCause:
    """One row of the manual's table: where to look, why, and what to do."""

    check_point: str
    cause: str
    correction: str


@dataclass(frozen=True, slots=True)
class EndCodeInfo:
    """The manual's description of one end code (main code + sub code)."""

    code: int
    main_name: str
    sub_name: str
    causes: tuple[EndCodeCause, ...]


# Manual 5-1-3 "End Codes", transcribed row by row. Format, one item per line:
#   "MM Main name"                        a main code
#   "MMSS Sub name"                       a sub code (of the main code above)
#   "  check point | cause | correction"  one probable cause; lines indented by four spaces
#                                         continue the cause above
# "---" in the check point column means the manual names none.
#
# Reconstructed where the manual's table is garbled (main codes 22/23/24): its rows list
# "07: Specified node not polling node" and "08: Step cannot be executed" under main code 23,
# ahead of 23's 01/02, and "03: Clock missing" under a second "24: Cannot start/stop" row
# followed by an empty "--- --- ---" row. Sub codes are listed in ascending order everywhere
# else, and 07/08 are mode/execution faults (main 22 "Not executable in current mode"), while a
# missing clock is a missing device (main 23 "No such device"; 24 has only "01: Table missing").
# So: 2207 and 2208 belong to main 22, 2303 "Clock missing" to main 23, and the empty row is
# dropped. The second cause of 2003 has an empty check point cell (a merged cell): "Table".
# Texts the manual leaves as "---" and we filled in: the cause and correction of 0000, the
# corrections of 2004, 2108 and 4001.
_TABLE = """
00 Normal completion
0000 Normal completion
  --- | The command completed normally. | None needed.
0001 Service canceled
  --- | Service was canceled. | Check the capacity of the destination area in the third node.
  Data link status | Service was canceled. | Check the status of the data link.
01 Local node error
0101 Local node not in network
  Network status of local node | Local node is not participating in the network. | Connect the node
    to the network.
0102 Token timeout
  Maximum node address | Token does not arrive. | Set the local node to within the maximum node
    address.
0103 Retries failed
  --- | Send was not possible during the specified number of retries. | Execute a communications
    test between the nodes and re-examine the system environment if it fails.
0104 Too many send frames
  Number of enabled send frames | Cannot send because maximum number of event frames exceeded. |
    Check event execution on the network and reduce the number of events per cycle. Increase the
    maximum number of event frames.
0105 Node address range error
  Node address | Node address setting error occurred. | Check the settings of the rotary switches
    to be sure that the address is within range and that each address is set only once in the same
    network.
0106 Node address duplication
  Node addresses | The same node address has been set twice in the same network. | Change the
    address of one of the nodes with the same address.
02 Destination node error
0201 Destination node not in network
  INS indicator on Unit | The destination node is not in the network. | Add the destination node to
    the network.
0202 Unit missing
  Instruction control data | There is no Unit with the specified unit address. | Check the
    destination unit address.
0203 Third node missing
  Instruction control data | The third node does not exist. | Check the unit address of the third
    node. Check the node address of the third node in the send data for CMND(490).
  Command data | Broadcasting was specified. | Specify only one node for the third node.
0204 Destination node busy
  --- | The destination node is busy. | Increase the number of retries or review the system so that
    the destination node does not receive so many messages.
0205 Response timeout
  --- | The message was destroyed by noise. | Increase the number of retries or test communications
    between nodes to see if there is too much noise.
  Instruction control data | The response monitor time is too short. | Increase the length of the
    response monitor time.
  Error history | The send/receive frame was discarded. | Take appropriate measures based on the
    error history.
03 Controller error
0301 Communications controller error
  Unit/Board indicators | An error occurred in the communications controller. | Take appropriate
    measures based on the operation manuals for the related Units/Boards.
0302 CPU Unit error
  CPU Unit indicators at destination node | A CPU error occurred in the destination CPU Unit. |
    Clear the error from the CPU Unit based on its operation manuals.
0303 Controller error
  Board indicators | A response was not returned because an error occurred in the Board. | Check
    network communications status and restart the Board. If the problem persists, replace the
    Board.
0304 Unit number error
  Unit number | The unit number was set incorrectly. | Set the rotary switches correctly, being
    sure the unit numbers are within range and that each number is used only once.
04 Service unsupported
0401 Undefined command
  Command code | The Unit/Board does not support the specified command code. | Check the command
    code.
0402 Not supported by model/version
  Unit model and version | The command cannot be executed because the model or version is
    incorrect. | Check the model number and version.
05 Routing table error
0501 Destination address setting error
  Routing table | The destination network or node address is not set in the routing tables. |
    Register the destination network and node in the routing tables.
0502 No routing tables
  Routing table | Relaying is not possible because there are no routing tables. | Set routing
    tables in the source node, designation node, and relay nodes.
0503 Routing table error
  Routing table | There is an error in the routing tables. | Set the routing tables correctly.
0504 Too many relays
  Network configuration | An attempt was made to send to a network that was over 3 networks away |
    Reconstruct the networks or change the routing tables so that commands are sent within a range
    of 3 networks or less.
10 Command format error
1001 Command too long
  Command data | The command is longer than the maximum permissible length. | Check the command
    format and correct the command data.
1002 Command too short
  Command data | The command is shorter than the minimum permissible length. | Check the command
    format and correct the command data.
1003 Elements/data don't match
  Command data | The designated number of elements differs from the number of write data items. |
    Check the number of elements and set data for each element.
1004 Command format error
  Command data | An incorrect format was used. | Check the command format and correct the command
    data.
1005 Header error
  Routing table | Either the relay table in the local node or the local network table in the relay
    node is incorrect. | Set the routing tables correctly.
11 Parameter error
1101 Area classification missing
  Memory area code in command data | The specified word does not exist in the memory area or there
    is no EM Area. | Check the memory areas and parameter codes in the command and correct the
    command data.
1102 Access size error
  Access size specification in command data | The access size specification is incorrect or an odd
    word address is specified. | Check the memory areas and access size and correct the access
    size.
1103 Address range error
  Starting address in command data | The start address in command process is beyond the accessible
    area. | Check the area being processed and set the correct range.
1104 Address range exceeded
  Starting address and number of elements in command data | The end address in command process is
    beyond the accessible area. | Check the area being processed and set the correct range.
  Data link tables | The total number of words is beyond the limit. | Correct the data link tables.
1106 Program missing
  Program number in command data | FFFF hex was not specified. | Specify FFFF hex.
1109 Relational error
  Command data | A large-small relationship in the elements in the command data is incorrect. |
    Check the command data and correct the relationship between the elements.
  Data link table | A node not set in the common link parameters is set as a refresh parameter. |
    Correct the data link tables.
110A Duplicate data access
  I/O access in CPU Unit | Differential monitoring was specified during data tracing or data
    tracing was specified during differential monitoring. | Abort the current process or wait until
    it ends before executing the command.
  Data link tables | The same node address is specified more than once. | Correct the data link
    tables.
110B Response too long
  Number of elements in command data | The response format is longer than the maximum permissible
    length. | Check the command format and correct the number of elements.
110C Parameter error
  Parameters in command data | There is an error in one of the parameter settings. | Check the
    command data and correct the parameters.
  Data link table file | There is an error in the file. | Check the contents of the file.
20 Read not possible
2002 Protected
  --- | The program area is protected. | Release protection from a Programming Device and then
    execute the command.
2003 Table missing
  Table | A table has not been registered. | Register a table.
  Table | There is an error in the table. | Correct the table.
2004 Data missing
  --- | The search data does not exist. | Check the data being searched for.
2005 Program missing
  Program number in command data | A non-existing program number has been specified. | Check the
    program numbers and specify a valid one.
2006 File missing
  File name and file device | The file does not exist at the specified file device. | Check the
    path and file name, and correct them.
2007 Data mismatch
  Contents of memory being compared | A data being compared is not the same. | Check memory
    contents and use the correct data.
  --- | A file read operation failed. | Check the contents of the file.
21 Write not possible
2101 Read-only
  --- | The specified area is read-only. | If the area is protected using a switch setting, release
    protection and then execute the command. If the area is permanently read-only, the command
    cannot be executed.
2102 Protected
  --- | The program area is protected. | Release protection from a Programming Device and then
    execute the command.
  PLC Setup | Writing is not possible because automatic data link table generation has been
    specified. | Change the PLC Setup so that the data link tables can be manually written.
2103 Cannot register
  Number of files in file device | The file cannot be created because the limit has been exceeded.
    | Delete any unnecessary files or create more file memory.
  Number of files open | The maximum number of files has already been opened for the system limit.
    | Close one or more files and then execute the command.
2105 Program missing
  Program number in command data | A non-existing program number has been specified. | Check the
    program numbers and specify a valid one.
2106 File missing
  File name | The file does not exist at the specified file device. | Correct the file name and
    then execute the command.
2107 File name already exists
  File name | A file with the same name already exists in the specified file device. | Change the
    name of the file being written and then execute the command.
2108 Cannot change
  Contents of memory being changed | The change cannot be made because doing so would create a
    problem. | Check the contents of memory being changed.
22 Not executable in current mode
2201 Not possible during execution
  --- | The mode is incorrect. | Check the mode.
  Data link status | The data link is operating. | Check the status of the data links.
2202 Not possible while running
  --- | The mode is incorrect. | Check the mode.
  Data link status | The data links are active. | Check the status of the data links.
2203 Wrong PLC mode
  --- | The PLC is in PROGRAM mode. | Check the modes of the PLC and computer.
2204 Wrong PLC mode
  --- | The PLC is in DEBUG mode. | Check the modes of the PLC and computer.
2205 Wrong PLC mode
  --- | The PLC is in MONITOR mode. | Check the modes of the PLC and computer.
2206 Wrong PLC mode
  --- | The PLC is in RUN mode. | Check the modes of the PLC and computer.
2207 Specified node not polling node
  --- | The specified node is not the polling node. | Check node functioning as the polling node
    for the network.
2208 Step cannot be executed
  --- | The mode is incorrect. | Check step status.
23 No such device
2301 File device missing
  Unit configuration | The specified memory does not exist as a file device. | Mount memory or
    format EM as file memory.
2302 Memory missing
  --- | There is no file memory. | Check the file memory to see if it is mounted.
2303 Clock missing
  --- | There is no clock. | Check the model.
24 Cannot start/stop
2401 Table missing
  Data link tables | The data link tables have not been registered or they contain an error. | Set
    the data link tables.
25 Unit error
2502 Memory error
  Contents of memory being processed | The contents of memory contains an error. | Transfer the
    correct contents to memory.
2503 I/O setting error
  I/O Unit configuration | The registered I/O tables do not agree with the actual I/O
    configuration. | Correct the I/O tables or the I/O configuration.
2504 Too many I/O points
  Number of I/O in registered I/O tables | There are too many I/O points and remote I/O points
    registered. | Change the registered I/O table so that it is within the limit.
2505 CPU bus error
  CPU bus line | An error occurred in data transfer between the CPU and a CPU Bus Unit. | Check
    Units, Boards, and cables to be sure they are connected correctly and then execute the ERROR
    CLEAR command.
2506 I/O duplication
  Rack numbers, Unit numbers, and I/O addresses in PLC Setup | The same number/address was set more
    than once. | Check the PLC Setup and correct the numbers/addresses so that each is used only
    once.
2507 I/O bus error
  I/O bus line | An error occurred in data transfer between the CPU and an I/O Unit. | Check Units,
    Boards, and cables to be sure they are connected correctly and then execute the ERROR CLEAR
    command.
2509 SYSMAC BUS/2 error
  SYSMAC BUS/2 transmission path | An error occurred in data transfer on the SYSMAC BUS/2 line. |
    Check Units, Boards, and cables to be sure they are connected correctly and then execute the
    ERROR CLEAR command.
250A CPU Bus Unit error
  CPU Bus Unit transmission path | An error occurred in data transfer for a CPU Bus Unit. | Check
    Units, Boards, and cables to be sure they are connected correctly and then execute the ERROR
    CLEAR command.
250D SYSMAC BUS No. duplication
  Word settings | The same word is allocated more than once. | Check the I/O tables and correct the
    allocations.
250F Memory error
  Status of memory being processed | A memory error has occurred in internal memory, a memory card,
    or EM file memory. | For internal memory, write the correct data and then execute the command.
    For a memory card or EM file memory, the file data has been destroyed. Execute the FILE MEMORY
    FORMAT command. If the problem persists, replace the memory.
2510 SYSMAC BUS terminator missing
  --- | Terminators have not been set. | Set the terminators correctly.
26 Command error
2601 No protection
  Command protection for program area | The specified area is not protected. | An attempt was made
    to clear protection on an area that is not protected, i.e., there is no reason to clear
    protection.
2602 Incorrect password
  --- | An incorrect password has been specified. | Specify the correct password.
2604 Protected
  --- | The specified area is protected. | Clear protection from a Programming Device and then
    execute the command.
  Number of commands being executed | The node receiving the command is already processing 5
    commands. | Wait for current processing to end or force the end of a current process and then
    execute the command.
2605 Service already executing
  --- | The service is being executed. | Wait for the service to end or force the end of the
    service and then execute the command.
2606 Service stopped
  --- | The service is not being executed. | If necessary, start the service.
2607 No execution right
  LNK indicator on Unit/Board | The right to execute the service has not been obtained. | The local
    node is not in the data link. Execute the command from a node that is participating in the data
    link.
  --- | A response was not returned because a buffer error occurred. | Restart the Board. If the
    problem persists, replace the Board.
2608 Settings not complete
  Settings required before execution | The settings required before executing the service have not
    been made. | Make the required settings.
2609 Necessary items not set
  Command data | The required elements have not been set in the command data. | Check the command
    format and set the required elements in the command data.
260A Number already defined
  Action numbers and transition numbers of program in program area | The specified action/
    transition number has already been registered in a previous program. | Check the
    action/transition numbers to ones that are not being used and then execute the command.
260B Error will not clear
  Cause of error being cleared | The cause of the error has not been removed. | Remove the cause of
    the error and then execute ERROR CLEAR.
30 Access right error
3001 No access right
  --- | The access right is held by another device. (Online editing is being executed from another
    node or ACCESS RIGHT ACQUIRE or ACCESS RIGHT FORCE ACQUIRE has been executed by another node.)
    | Wait until the access right is released and then execute the command. ACCESS RIGHT ACQUIRE or
    ACCESS RIGHT FORCE ACQUIRE can be executed to obtain the access right, but this may adversely
    affect processing by the node that previously held the access right.
40 Abort
4001 Service aborted
  --- | Service was aborted with ABORT command. | None needed: the service was aborted on request.
"""


def _parse_table(text: str) -> tuple[dict[int, EndCodeInfo], dict[int, str]]:
    mains: dict[int, str] = {}
    subs: dict[int, tuple[str, list[str]]] = {}
    main = -1
    code = -1
    for line in text.splitlines():
        if not line.strip():
            continue
        if line.startswith("    "):
            rows = subs[code][1]
            rows[-1] += " " + line.strip()
        elif line.startswith("  "):
            subs[code][1].append(line.strip())
        else:
            number, name = line.split(" ", 1)
            if len(number) == 2:
                main = int(number, 16)
                mains[main] = name
            else:
                code = int(number, 16)
                if code >> 8 != main or code in subs:
                    raise AssertionError(f"end code table out of order at {number}")
                subs[code] = (name, [])
    table: dict[int, EndCodeInfo] = {}
    for code, (name, rows) in subs.items():
        causes: list[EndCodeCause] = []
        for row in rows:
            check, cause, correction = (cell.strip() for cell in row.split(" | "))
            causes.append(EndCodeCause("" if check == "---" else check, cause, correction))
        table[code] = EndCodeInfo(code, mains[code >> 8], name, tuple(causes))
    return table, mains


#: Every end code of manual 5-1-3, keyed by the code without flag bits, e.g. ``0x1104``.
END_CODES: dict[int, EndCodeInfo]
#: Main code (``0x00``-``0x40``) → the manual's name, for sub codes not in the table.
MAIN_CODE_NAMES: dict[int, str]
END_CODES, MAIN_CODE_NAMES = _parse_table(_TABLE)

#: End codes a command's own section gives that 5-1-3's table lacks (named from that section).
SECTION_END_CODES: dict[int, EndCodeInfo] = {
    0x1108: EndCodeInfo(
        0x1108,
        MAIN_CODE_NAMES[0x11],
        "Too many words",
        (
            EndCodeCause(
                "Number of words in command data (PARAMETER AREA READ, 5-3-7)",
                "More than 498 words were asked for; the first 498 were read and returned.",
                "Read at most 498 words per command.",
            ),
        ),
    ),
}


@dataclass(frozen=True, slots=True)
class EndCode:
    """A decoded end code: ``raw`` is the 16-bit word as received, flags included."""

    raw: int

    @classmethod
    def from_bytes(cls, mres: int, sres: int) -> EndCode:
        return cls((mres << 8) | sres)

    @property
    def code(self) -> int:
        """The end code with the flag bits masked off (``0x7F3F``)."""
        return self.raw & END_CODE_MASK

    @property
    def main(self) -> int:
        return (self.raw >> 8) & 0x7F

    @property
    def sub(self) -> int:
        return self.raw & 0x3F

    @property
    def relay_error(self) -> bool:
        """Bit 15: a relay point failed to forward the command (a 2-byte trailer follows)."""
        return bool(self.raw & RELAY_ERROR_FLAG)

    @property
    def fatal_cpu_error(self) -> bool:
        """Bit 7: the destination CPU Unit has a fatal error."""
        return bool(self.raw & FATAL_CPU_ERROR_FLAG)

    @property
    def non_fatal_cpu_error(self) -> bool:
        """Bit 6: the destination CPU Unit has a non-fatal error (e.g. battery)."""
        return bool(self.raw & NON_FATAL_CPU_ERROR_FLAG)

    @property
    def is_normal(self) -> bool:
        """True for a normal completion (``0000``, also with bit 6/7 flags set)."""
        return self.code == 0x0000 and not self.relay_error

    @property
    def info(self) -> EndCodeInfo | None:
        code = self.code
        return END_CODES.get(code) or SECTION_END_CODES.get(code)

    @property
    def name(self) -> str:
        info = self.info
        if info is not None:
            if info.sub_name == info.main_name:
                return info.sub_name
            return f"{info.main_name}: {info.sub_name}"
        main = MAIN_CODE_NAMES.get(self.main)
        return f"{main}: unknown sub code {self.sub:02X}" if main else "unknown end code"

    @property
    def cause(self) -> str:
        info = self.info
        return " / ".join(c.cause for c in info.causes if c.cause) if info else ""

    @property
    def correction(self) -> str:
        info = self.info
        return " / ".join(c.correction for c in info.causes if c.correction) if info else ""

    def __str__(self) -> str:
        flags = []
        if self.relay_error:
            flags.append("relay error")
        if self.fatal_cpu_error:
            flags.append("fatal CPU error")
        if self.non_fatal_cpu_error:
            flags.append("non-fatal CPU error")
        suffix = f" [{', '.join(flags)}]" if flags else ""
        return f"{self.code:04X} {self.name}{suffix}"


NORMAL = EndCode(0x0000)
