"""Not built yet: exits non-zero so that nobody mistakes it for a working node."""
import sys


def main(args=None) -> None:
    sys.exit(f'{__name__}: not implemented yet')


if __name__ == '__main__':
    main()
