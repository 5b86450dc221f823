from stack.apps.cli import main

main()
