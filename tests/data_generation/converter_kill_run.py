"""Run the Spike-Cityscapes converter's command line and SIGKILL it at a
chosen file-system step (driver of ``test_converter_survives_sigkill``;
not a test itself).

    python converter_kill_run.py STEP WHEN -- [spike_cityscapes.py args]

Every ``os.replace`` (an atomic write landing) and ``os.remove`` is a step;
the process kills itself just ``before`` or ``after`` step ``STEP``
(1-based): before a replace, the temporary file is written but not in
place, as when the kill lands mid-write. It prints the number of steps on
a run that ends without reaching ``STEP``.
"""
import os
import runpy
import signal
import sys

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(
    os.path.abspath(__file__))))


def main():
    step, when = int(sys.argv[1]), sys.argv[2]
    args = sys.argv[sys.argv.index('--') + 1:]
    count = 0

    def counted(function):
        def wrapper(*a, **k):
            nonlocal count
            count += 1
            if count == step and when == 'before':
                os.kill(os.getpid(), signal.SIGKILL)
            result = function(*a, **k)
            if count == step and when == 'after':
                os.kill(os.getpid(), signal.SIGKILL)
            return result
        return wrapper

    os.replace = counted(os.replace)
    os.remove = counted(os.remove)
    script = os.path.join(ROOT, 'tools', 'dataset_converters',
                          'spike_cityscapes.py')
    sys.argv = [script] + args
    runpy.run_path(script, run_name='__main__')
    print(f'steps={count}')


if __name__ == '__main__':
    main()
