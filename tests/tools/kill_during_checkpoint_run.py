"""Run ``tools/train.py`` and SIGKILL it halfway through writing its
``N``-th checkpoint (driver of ``test_interrupted_training.py``; not a test).

    python kill_during_checkpoint_run.py N -- [train.py arguments]

mmengine serialises a checkpoint in memory and writes the bytes with its
local file backend's ``put``; the ``N``-th ``put`` of a ``.pth`` writes half
of them, flushed to disk, and the process kills itself.
"""
import os
import runpy
import signal
import sys

from mmengine.fileio.backends import LocalBackend

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(
    os.path.abspath(__file__))))


def main():
    target = int(sys.argv[1])
    args = sys.argv[sys.argv.index('--') + 1:]
    put = LocalBackend.put
    count = 0

    def dying_put(self, obj, filepath):
        nonlocal count
        if str(filepath).endswith('.pth'):
            count += 1
            if count == target:
                with open(filepath, 'wb') as f:
                    f.write(obj[:len(obj) // 2])
                    f.flush()
                    os.fsync(f.fileno())
                os.kill(os.getpid(), signal.SIGKILL)
        return put(self, obj, filepath)

    LocalBackend.put = dying_put
    script = os.path.join(ROOT, 'tools', 'train.py')
    sys.argv = [script] + args
    runpy.run_path(script, run_name='__main__')


if __name__ == '__main__':
    main()
