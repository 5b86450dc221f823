from stack.apps.cli import app

app(prog_name="drivestack")
