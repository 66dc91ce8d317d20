"""The Parallax Eddie control board, a second robot beside the Mega chair
(docs/eddie.md). One module per floor: ``firmware`` (the board's command interpreter
and Position Controller loop, pure), ``plant`` (the Eddie configuration of the pymunk
chair and its PING)))/IR sensors), ``board`` (the two as a live threaded board),
``robot`` (the host's navigation API over the ASCII protocol) and ``runner`` (the
scenario tool). This file imports none of them."""
