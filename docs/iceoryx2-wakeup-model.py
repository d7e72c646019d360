#!/usr/bin/env python3
"""Every interleaving of iceoryx2 0.10's event wake-up protocol, searched for a lost wake-up.

The protocol (iceoryx2-cal `event/common.rs` with the unix datagram trigger): a notifier
publishes its sample, then notifies: CAS idle -> pending (a listener left "notified" makes it
skip the rest), writes one datagram, CAS pending -> notified. The listener (thrusterd's loop)
waits on the socket; woken by it, it drains, then reads its samples and answers each; woken by
anything else it only reads. A lost wake-up: the listener waiting on an empty socket, no
notifier about to write, and either the state "notified" (every later notifier skips its write:
the listener is woken only by something else, docs/reliability.md, "The stall found") or a
sample unread.

    python3 docs/iceoryx2-wakeup-model.py

searches the drain as upstream has it (CAS notified -> idle, or a read and a store, then one
read of the socket) and as patched in vendor/iceoryx2-cal (every datagram read, then the state
stored idle), with 1-3 notifiers (the lockstep simulator is one), each bounded to 3 datagrams,
3 unread samples and 3 unread answers. Upstream prints the shortest interleaving that loses the
wake-up; patched prints that none does.
"""
import sys
from collections import deque

I, P, N = 0, 1, 2


def notifier_steps(s):
    st, sock, inbox, ans, pcs, dpc = s
    out = []
    for i, pc in enumerate(pcs):
        def go(st2, sock2, inbox2, ans2, pc2, what):
            l = list(pcs)
            l[i] = pc2
            out.append(((st2, sock2, inbox2, ans2, tuple(l), dpc), f"notifier {i}: {what}"))
        if pc == 'publish':
            go(st, sock, inbox + 1, ans, 'cas', 'publishes a sample')
        elif pc == 'cas':
            if st == I:
                go(P, sock, inbox, ans, 'send', 'CAS idle -> pending')
            elif st == P:
                go(st, sock, inbox, ans, 'send', 'CAS fails (pending): writes anyway')
            else:
                go(st, sock, inbox, ans, 'answer', 'sees notified: skips its write')
        elif pc == 'send':
            go(st, sock + 1, inbox, ans, 'cas2', 'writes a datagram')
        elif pc == 'cas2':
            go(N if st == P else st, sock, inbox, ans, 'answer',
               'CAS pending -> notified' + ('' if st == P else ' fails'))
        elif pc == 'answer' and ans > 0:
            go(st, sock, inbox, ans - 1, 'publish', 'takes an answer')
    return out


def listener_steps(s, patched):
    st, sock, inbox, ans, pcs, pc = s
    out = []

    def go(st2, sock2, inbox2, ans2, pc2, what):
        out.append(((st2, sock2, inbox2, ans2, pcs, pc2), f"listener: {what}"))
    if pc == 'wait':
        if sock > 0:
            go(st, sock, inbox, ans, 'drain', 'woken by the socket')
        else:
            go(st, sock, inbox, ans, 'read', 'woken by something else')
    elif patched:
        if pc == 'drain':
            if sock > 0:
                go(st, sock - 1, inbox, ans, 'drain', 'reads a datagram')
            else:
                go(st, sock, inbox, ans, 'store', 'finds the socket empty')
        elif pc == 'store':
            go(I, sock, inbox, ans, 'read', 'stores idle')
    else:
        if pc == 'drain':
            if st == N:
                go(I, sock, inbox, ans, 'empty', 'CAS notified -> idle')
            else:
                go(st, sock, inbox, ans, 'try', 'CAS fails')
        elif pc == 'empty':
            go(st, max(sock - 1, 0), inbox, ans, 'read', 'empties the socket (one read)')
        elif pc == 'try':
            go(st, max(sock - 1, 0), inbox, ans, 'store', 'try_wait (one read)')
        elif pc == 'store':
            go(I, sock, inbox, ans, 'empty', 'stores idle')
    if pc == 'read':
        if inbox > 0:
            go(st, sock, inbox - 1, ans + 1, 'read', 'reads a sample, answers it')
        else:
            go(st, sock, inbox, ans, 'wait', 'waits')
    return out


def search(patched, notifiers):
    start = (I, 0, 0, 0, ('publish',) * notifiers, 'wait')
    parent = {start: None}
    queue = deque([start])
    while queue:
        s = queue.popleft()
        st, sock, _, _, pcs, pc = s
        # Lost: "notified" with an empty socket (every later write skipped), or a sample
        # unread with nothing left to wake the listener for it.
        quiet = sock == 0 and pc == 'wait' and not {'cas', 'send', 'cas2'} & set(pcs)
        if quiet and (st == N or s[2] > 0):
            path = []
            while parent[s] is not None:
                s, what = parent[s][0], (parent[s][1], s)
                path.append(what)
            return len(parent), list(reversed(path))
        for n, what in notifier_steps(s) + listener_steps(s, patched):
            if max(n[1], n[2], n[3]) > 3 or n in parent:
                continue
            parent[n] = (s, what)
            queue.append(n)
    return len(parent), None


def main():
    for patched in (False, True):
        for notifiers in (1, 2, 3):
            states, path = search(patched, notifiers)
            name = 'patched' if patched else 'upstream'
            if path is None:
                print(f"{name}, {notifiers} notifier(s): {states} states, no lost wake-up")
                continue
            print(f"{name}, {notifiers} notifier(s): {states} states searched, a lost wake-up:")
            for what, (st, sock, inbox, ans, pcs, pc) in path:
                print(f"    {what:52s} state {'IPN'[st]}, socket {sock}, samples {inbox}, answers {ans}")
    return 0


if __name__ == '__main__':
    sys.exit(main())
