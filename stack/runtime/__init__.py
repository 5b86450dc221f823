"""The process runtime every command runs on: where work items run (here, processes, Ray tasks), what
a stop signal does, the watchdog over a local Ray instance, one owner per results folder, and result
files written whole. It imports nothing else of `stack`."""
