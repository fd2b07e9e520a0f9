"""The peak memory of code run in a fresh process, as the tests of issue 26 measure it.

:data:`PROBE` is prepended to a child's code: ``reset_peak()`` starts the measurement and
``memory("VmHWM")`` / ``memory("VmRSS")`` read the peak and the current size, in bytes.
``getrusage``'s ``ru_maxrss`` would not do: it keeps the RSS of the parent at the fork (pytest's,
hundreds of MB into a full run), not this process's.
"""

PROBE = '''
def memory(field):
    for line in open("/proc/self/status"):
        if line.startswith(field):
            return int(line.split()[1]) * 1024


def reset_peak():
    with open("/proc/self/clear_refs", "w") as f:
        f.write("5")  # VmHWM is set back to the RSS now
'''
