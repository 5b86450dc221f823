"""The episode record every report reads (`episode_result.EpisodeResult`) and the declarations of its
fields (`episode_fields`: unit, summary entries, table rows, intervals): the loop fills it, runs
aggregate it, the commands print it."""
