# firmware/: the board, its disciplined clock (docs/TIME.md) and its plants,
# portable C99 without a heap (docs/BOARD.md); vmac-board (firmware/posix/)
# and `vmac test` (core/vtest/) run it. Uses proto.
board_SRC  := firmware/board.c firmware/timed.c firmware/clock.c firmware/plant.c firmware/report.c $(wildcard firmware/plants/*.c)
board_LIBS := -lm
