#!/usr/bin/python3
"""operator_machine.py SRC DST: SRC (a sim3 copy) with homing required, a home switch
on each simulated axis and each axis's home sequence (Z first, then X and Y), for the
operator-function tests. The switches close 4 mm inside each axis's travel
end, where the axes search for them (X, Y towards -, Z towards +)."""
import re
import sys

src, dst = sys.argv[1], sys.argv[2]
text = open(src).read()
homes = {
    "X": ("-1", "-4", "1", "0.002"),
    "Y": ("-1", "-4", "1", "0.002"),
    "Z": ("1", "4", "0", "0.002"),
}


def axis_block(m):
    block = m.group(0)
    name = re.search(r"- name: (\w+)", block).group(1)
    d, sw, order, sigma = homes[name]
    seed = {"X": 11, "Y": 12, "Z": 13}[name]
    block = re.sub(r"sim: \{([^}]*)\}",
                   lambda s: "sim: {%s, home_switch_mm: %s, home_switch_sigma_mm: %s, home_switch_seed: %d}"
                   % (s.group(1), sw, sigma, seed), block)
    block += ("    home: {method: switch, search_velocity_mm_s: 10, latch_velocity_mm_s: 1, direction: %s,\n"
              "           switch_position_mm: %s, position_mm: 0, backoff_mm: 1, order: %s}\n" % (d, sw, order))
    return block


text = re.sub(r"  - name: \w+\n(?:    .*\n)+", axis_block, text)
text += "\noperator:\n  homing_required: true\n  jog_keepalive_timeout_s: 0.2\n  mdi_directory: %s\n" % sys.argv[3]
open(dst, "w").write(text)
